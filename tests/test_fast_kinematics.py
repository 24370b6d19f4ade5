"""The fast observation equals highway-env's stock KinematicObservation, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from highway_env.envs.common.observation import KinematicObservation

from zodrive.envs import load_preset, make_env
from zodrive.envs.fast_kinematics import FastKinematicObservation

ALL_FEATURES = ["presence", "x", "y", "vx", "vy", "heading", "cos_h", "sin_h", "cos_d", "sin_d",
                "long_off", "lat_off", "ang_off"]

# (preset, preset overrides, the observation options compared along one trajectory)
CASES = [
    ("discrete", [], [
        {},
        {"features_range": {"x": [-10, 10], "y": [-2, 2], "vx": [-1, 1], "vy": [-1, 1]}},
        {"features_range": None},  # highway-env's own default ranges
        {"order": "shuffled", "observe_intentions": True, "features": ALL_FEATURES},
        {"clip": False},
    ]),
    ("continuous", [], [{}, {"normalize": False, "clip": False, "features": ALL_FEATURES}]),
    ("discrete", ["highway.vehicles_count=50", "highway.vehicles_density=1.5"], [{"see_behind": True}]),
    ("discrete", ["highway.vehicles_count=0"], [{}]),  # empty road: presence padding
    ("continuous", ["highway.vehicles_count=40"], [{"absolute": True, "vehicles_count": 8}]),
]


def _options(config: dict, extra: dict) -> dict:
    opts = {k: v for k, v in config["highway"]["observation"].items() if k != "type"}
    opts.update(extra)
    return opts


@pytest.mark.integration
@pytest.mark.parametrize("preset,overrides,extras", CASES)
def test_fast_observation_matches_stock(preset: str, overrides: list[str], extras: list[dict]) -> None:
    """Every option set is compared on the same 100+ states: the trajectory is the costly part."""
    config = load_preset(preset, overrides + ["highway.simulation_frequency=5", "highway.policy_frequency=2",
                                              "highway.duration=300",
                                              "highway.offroad_terminal=false"])
    env = make_env(config)
    states = 0
    for seed in range(12):
        if states >= 100:
            break
        env.reset(seed=seed)
        base = env.unwrapped
        env.action_space.seed(seed)
        pairs = [(KinematicObservation(base, **_options(config, extra)),
                  FastKinematicObservation(base, **_options(config, extra))) for extra in extras]
        for _ in range(40):
            for stock, fast in pairs:
                state = base.np_random.bit_generator.state
                want = stock.observe()
                base.np_random.bit_generator.state = state  # "shuffled" draws from the env RNG
                got = fast.observe()
                assert got.dtype == want.dtype and got.shape == want.shape
                np.testing.assert_array_equal(got, want)
            states += 1
            action = env.action_space.sample()
            if preset == "discrete":
                action = [4, 4, 1, 0, 2, 4][int(action)]  # mostly slow: long, varied episodes
            else:
                action = action * np.array([1.0, 0.05], dtype=np.float32)  # stay near the road
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                break
    assert states >= 100


def test_fast_observation_is_the_preset_default() -> None:
    env = make_env(load_preset("discrete"))
    env.reset(seed=0)
    assert type(env.unwrapped.observation_type) is FastKinematicObservation
    env = make_env(load_preset("discrete", ["highway.observation.type=Kinematics"]))
    env.reset(seed=0)
    assert type(env.unwrapped.observation_type) is KinematicObservation


def test_same_trajectory_with_either_observation() -> None:
    """Same seed and actions: identical observations and rewards along a whole episode."""
    runs = []
    for kind in ("FastKinematics", "Kinematics"):
        env = make_env(load_preset("discrete", [f"highway.observation.type={kind}"]))
        obs, _ = env.reset(seed=7)
        trace = [obs]
        for t in range(120):
            obs, reward, terminated, truncated, _ = env.step([3, 1, 4, 0, 2][t % 5])
            trace.append(obs)
            trace.append(np.array([reward]))
            if terminated or truncated:
                break
        runs.append(trace)
    assert len(runs[0]) == len(runs[1])
    for a, b in zip(*runs):
        np.testing.assert_array_equal(a, b)
