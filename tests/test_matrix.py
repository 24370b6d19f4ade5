"""The matrix: every supported algorithm x three scenarios, trained briefly by plain
stable-baselines3, saved with `model.save`, then evaluated under attack by the CLI.

Discrete-action algorithms run on highway, merge and roundabout. highway-env's merge and
roundabout compute their reward from a meta-action index and fail on continuous actions, so
the continuous-action algorithms run on highway, intersection and racetrack instead (the
scenarios whose continuous variants highway-env supports).

Each cell checks what a user relies on: the zip loads safely, the attack stays inside its
budget, and every query is counted. Budgets are tiny (a 128-step training, one short
episode with three attack iterations per step) so the whole matrix runs in the default suite.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

sb3_contrib = pytest.importorskip("sb3_contrib")
from stable_baselines3 import A2C, DDPG, DQN, PPO, SAC, TD3  # noqa: E402

from zodrive.cli import main  # noqa: E402
from zodrive.envs import load_preset, make_env  # noqa: E402

SMALL = {"buffer_size": 2000, "learning_starts": 64, "batch_size": 32}
ALGOS = {
    "dqn": (DQN, SMALL), "qrdqn": (sb3_contrib.QRDQN, SMALL), "ddpg": (DDPG, SMALL), "td3": (TD3, SMALL),
    "sac": (SAC, SMALL), "tqc": (sb3_contrib.TQC, SMALL), "ppo": (PPO, {"n_steps": 128, "batch_size": 64}),
    "a2c": (A2C, {}),
}
CONTINUOUS = {"ddpg", "td3", "sac", "tqc"}
# cheap versions of each scenario: few vehicles, 5 Hz simulation, short episodes
CHEAP = {
    "highway": ["highway.vehicles_count=5", "highway.simulation_frequency=5", "highway.duration=8"],
    "merge": ["highway.simulation_frequency=5", "max_episode_steps=8"],
    "roundabout": ["highway.simulation_frequency=5", "highway.duration=8"],
    "intersection": ["highway.simulation_frequency=5", "highway.duration=8", "highway.initial_vehicle_count=3",
                     "highway.spawn_probability=0"],
    "racetrack": ["highway.simulation_frequency=5", "max_episode_steps=8", "highway.other_vehicles=1"],
}
SCENARIOS = {"discrete": ("highway", "merge", "roundabout"), "continuous": ("highway", "intersection", "racetrack")}
CELLS = [(algo, scenario) for algo in sorted(ALGOS)
         for scenario in SCENARIOS["continuous" if algo in CONTINUOUS else "discrete"]]
EPS = 0.05


@pytest.mark.parametrize("algo,scenario", CELLS)
def test_train_save_then_attack(tmp_path: Path, algo: str, scenario: str, capsys) -> None:
    overrides = list(CHEAP[scenario])
    if algo in CONTINUOUS and scenario != "racetrack":  # the same scenario with continuous actions
        overrides.append("highway.action={type: ContinuousAction}")
    cls, options = ALGOS[algo]
    model = cls("MlpPolicy", make_env(load_preset(scenario, overrides)), seed=0, device="cpu", **options)
    model.learn(128)
    model.save(tmp_path / algo)  # plain SB3: no zodrive in the file
    args = ["evaluate", str(tmp_path / f"{algo}.zip"), "--preset", scenario, "--episodes", "1",
            "--attack", "random-search", "--eps", str(EPS), "--steps", "3", "--target", "none",
            "--out", str(tmp_path / "eval"), "--no-progress"]
    for override in overrides:
        args += ["--env-set", override]
    assert main(args) == 0, capsys.readouterr().err
    summary = json.loads((tmp_path / "eval" / "summary.json").read_text())
    steps = [json.loads(line) for line in (tmp_path / "eval" / "steps.jsonl").read_text().splitlines()]
    assert summary["max_linf"] <= EPS + 1e-6  # inside the budget
    assert len(steps) == summary["mean_length"] >= 1
    assert sum(s["queries"] for s in steps) == round(summary["queries_per_step"] * len(steps))  # counted once
    assert all(1 <= s["queries"] <= 2 + 3 * 20 for s in steps)  # clean + start + T iterations of q directions
    assert np.isfinite(summary["mean_return"])
