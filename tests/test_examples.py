"""The examples in examples/ run as documented."""

from __future__ import annotations

import importlib.util
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_own_sb3_loop_attacks_a_cartpole_dqn() -> None:
    spec = importlib.util.spec_from_file_location("own_sb3_loop", EXAMPLES / "own_sb3_loop.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    returns = module.main(train_steps=6000, episodes=2)
    assert returns["clean"] > 0 and returns["attacked"] > 0
    # the policy acts otherwise on what it is fed than on the truth (a pass-through wrapper: never)
    assert returns["flipped"] > 0
    assert returns["queries"] > 2 * returns["attacked"]  # and the attacker paid for it in queries
