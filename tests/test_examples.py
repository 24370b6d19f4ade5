"""The examples in examples/ run as documented."""

from __future__ import annotations

import importlib.util
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_own_sb3_loop_attacks_a_cartpole_dqn() -> None:
    spec = importlib.util.spec_from_file_location("own_sb3_loop", EXAMPLES / "own_sb3_loop.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    returns = module.main(train_steps=300, episodes=2)
    assert set(returns) == {"clean", "attacked"} and returns["clean"] > 0
