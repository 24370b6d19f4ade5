"""zodrive: black-box observation attacks on deep-RL driving policies, and defenses.

The Python API (`zodrive.api`), read on first use so that `import zodrive` stays light:

    import zodrive
    result = zodrive.evaluate(model, "highway-fast", "random-search", eps=0.05, episodes=20)
    result.summary["mean_return"], result.plot("returns.png")
    batch = zodrive.attack(model, observations, "highway-fast", "zo-signsgd", eps=0.05)
    env = zodrive.AttackWrapper(gym.make("highway-fast-v0"), model, attack="random-search", eps=0.05)
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"
__all__ = ["AttackSpec", "AttackWrapper", "Policy", "Result", "attack", "evaluate", "resolve"]

_HOMES = {"AttackWrapper": "zodrive.system", "Result": "zodrive.api", "attack": "zodrive.api",
          "evaluate": "zodrive.api", "AttackSpec": "zodrive.attacks.spec", "Policy": "zodrive.policies.policy",
          "resolve": "zodrive.policies.policy"}

if TYPE_CHECKING:
    from zodrive.api import Result, attack, evaluate
    from zodrive.attacks.spec import AttackSpec
    from zodrive.policies.policy import Policy, resolve
    from zodrive.system import AttackWrapper


def __getattr__(name: str) -> Any:
    if name not in _HOMES:
        raise AttributeError(f"module 'zodrive' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(_HOMES[name]), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])
