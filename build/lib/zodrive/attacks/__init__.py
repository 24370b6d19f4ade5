"""Black-box observation attacks: threat model, counting oracle, objectives, the family."""

from zodrive.attacks.base import Attack, AttackResult
from zodrive.attacks.objectives import make_objective
from zodrive.attacks.oracle import QueryBudgetExhausted, QueryOracle
from zodrive.attacks.registry import ATTACKS, make_attack
from zodrive.attacks.spec import AttackSpec, load_attack
from zodrive.attacks.threat import ThreatModel

__all__ = [
    "ATTACKS", "Attack", "AttackResult", "AttackSpec", "QueryBudgetExhausted", "QueryOracle",
    "ThreatModel", "load_attack", "make_attack", "make_objective",
]
