"""Presets, config merging and the 450-step episode."""

from __future__ import annotations

import numpy as np
import pytest

from zodrive.config import deep_merge, parse_override
from zodrive.envs import load_preset, make_env
from zodrive.errors import ZodriveError


def test_deep_merge_keeps_sibling_keys() -> None:
    base = {"highway": {"observation": {"type": "Kinematics", "vehicles_count": 5}, "lanes_count": 4}}
    merged = deep_merge(base, {"highway": {"observation": {"vehicles_count": 7}}})
    assert merged == {"highway": {"observation": {"type": "Kinematics", "vehicles_count": 7}, "lanes_count": 4}}
    assert base["highway"]["observation"]["vehicles_count"] == 5  # inputs untouched


def test_override_parses_yaml_values() -> None:
    assert parse_override("a.b=3") == {"a": {"b": 3}}
    assert parse_override("a=[1, 2]") == {"a": [1, 2]}
    assert parse_override("a.b=true") == {"a": {"b": True}}
    with pytest.raises(ZodriveError, match="KEY.PATH=VALUE"):
        parse_override("novalue")
    with pytest.raises(ZodriveError, match="empty key"):
        parse_override("a..b=1")


@pytest.mark.parametrize("preset,actions", [("discrete", 5), ("continuous", 2)])
def test_preset_spaces_and_bounds(preset: str, actions: int) -> None:
    config = load_preset(preset)
    hw = config["highway"]
    assert hw["vehicles_count"] == 20 and hw["observation"]["features_range"]["x"] == [-100, 100]
    assert hw["observation"]["features_range"]["vx"] == [-20, 20]
    env = make_env(config)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (5, 5) and obs.dtype == np.float32
    assert env.action_space.shape == (() if actions == 5 else (2,))
    if actions == 5:
        assert env.action_space.n == 5
    assert np.all(np.abs(obs) <= 1.0)


def test_continuous_preset_inherits_from_discrete() -> None:
    config = load_preset("continuous")
    assert config["highway"]["action"]["type"] == "ContinuousAction"
    assert config["highway"]["offroad_terminal"] is True
    assert config["highway"]["lanes_count"] == 4  # from the discrete base


def test_episode_lasts_exactly_450_decisions() -> None:
    """duration 30 s x 15 Hz alone gives 451 steps; the TimeLimit makes it 450."""
    env = make_env(load_preset("discrete", ["highway.vehicles_count=0"]))
    env.reset(seed=0)
    total, steps, done = 0.0, 0, False
    while not done:
        _, reward, terminated, truncated, _ = env.step(4)
        total += reward
        steps += 1
        done = terminated or truncated
    assert steps == 450 and truncated and not terminated
    assert 0 < total <= 450


def test_reward_is_normalized_per_step() -> None:
    env = make_env(load_preset("discrete"))
    env.reset(seed=3)
    for _ in range(30):
        _, reward, terminated, truncated, _ = env.step(3)
        assert 0.0 <= reward <= 1.0
        if terminated or truncated:
            break


def test_same_seed_same_episode() -> None:
    def rollout() -> list[float]:
        env = make_env(load_preset("discrete"))
        obs, _ = env.reset(seed=11)
        rewards = []
        for t in range(60):
            obs, r, term, trunc, _ = env.step(t % 5)
            rewards.append(r)
            if term or trunc:
                break
        return rewards

    assert rollout() == rollout()


@pytest.mark.parametrize(
    "name,overrides,message",
    [
        ("nope", [], "unknown preset"),
        ("discrete", ["highway.vehicles_count=-3"], "vehicles_count"),
        ("discrete", ["highway.observation.type=Lidar"], "observation.type"),
        ("discrete", ["max_episode_steps=0"], "max_episode_steps"),
        ("discrete", ["highway.action.type=Teleport"], "action.type"),
    ],
)
def test_bad_presets_are_clear_errors(name: str, overrides: list[str], message: str) -> None:
    with pytest.raises(ZodriveError, match=message):
        load_preset(name, overrides)


def _traffic_after(preset: str, steps: int) -> np.ndarray:
    """Every vehicle's position after `steps` IDLE decisions from seed 3."""
    env = make_env(load_preset(preset))
    env.reset(seed=3)
    for _ in range(steps):
        env.step(1)
    return np.array([v.position for v in env.unwrapped.road.vehicles])


def test_an_intersection_earlier_in_the_process_does_not_change_another_scenarios_traffic() -> None:
    from highway_env.vehicle.behavior import IDMVehicle

    before = _traffic_after("highway-fast", 8)
    _traffic_after("intersection", 2)  # highway-env sets IDMVehicle's jam distance and comfort accelerations here
    assert IDMVehicle.DISTANCE_WANTED == 7
    np.testing.assert_array_equal(_traffic_after("highway-fast", 8), before)


def test_two_scenarios_stepped_in_turn_are_refused() -> None:
    crossing = make_env(load_preset("intersection"))
    crossing.reset(seed=0)
    make_env(load_preset("highway-fast")).reset(seed=0)
    with pytest.raises(ZodriveError, match="driver model"):
        crossing.step(1)
