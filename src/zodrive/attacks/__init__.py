"""Black-box observation attacks: threat model, counting oracle, objectives, the family.

The names below are read lazily: `zodrive.attacks.schema` (the attack's options, which the
command line reads for its flags) loads without torch.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from zodrive.attacks.base import Attack, AttackResult
    from zodrive.attacks.objectives import make_objective
    from zodrive.attacks.oracle import QueryBudgetExhausted, QueryOracle
    from zodrive.attacks.registry import ATTACKS, make_attack
    from zodrive.attacks.spec import AttackSpec, load_attack
    from zodrive.attacks.threat import ThreatModel

_HOME = {
    "Attack": "base", "AttackResult": "base", "make_objective": "objectives", "QueryBudgetExhausted": "oracle",
    "QueryOracle": "oracle", "ATTACKS": "registry", "make_attack": "registry", "AttackSpec": "spec",
    "load_attack": "spec", "ThreatModel": "threat",
}

__all__ = [
    "ATTACKS", "Attack", "AttackResult", "AttackSpec", "QueryBudgetExhausted", "QueryOracle",
    "ThreatModel", "load_attack", "make_attack", "make_objective",
]


def __getattr__(name: str) -> Any:
    if name in _HOME:
        return getattr(importlib.import_module(f"zodrive.attacks.{_HOME[name]}"), name)
    raise AttributeError(f"module 'zodrive.attacks' has no attribute {name!r}")
