"""The shield's premise about highway-env's lane changes, measured on the real env (slow)."""

from __future__ import annotations

import numpy as np
import pytest

from zodrive.policies.resolve import load_victim
from zodrive.drivers.rules import MID_CHANGE_VY, ObservationRules
from zodrive.envs import load_preset, make_env
from zodrive.evaluation.rollout import act

pytestmark = pytest.mark.slow


def test_a_lane_change_moves_sideways_fast_until_it_reaches_the_target_lane() -> None:
    """While the ego is in the first half of a lane change (its target lane is not yet its lane),
    its lateral speed is at least MID_CHANGE_VY: then `ObservationRules` may tell from |vy| that
    a second change would aim one lane further. Seeds 60000+ (the constant was read on 50000+)."""
    preset = load_preset("discrete")
    env, driver = make_env(preset), load_victim("models/dqn-driver", preset)
    vy_range = ObservationRules(preset).scale[4]   # [m/s] the observation's vy is normalized by it
    speeds = []
    for seed in range(60000, 60008):
        obs, _ = env.reset(seed=seed)
        done = False
        while not done:
            ego = env.unwrapped.vehicle
            if ego.target_lane_index[2] != ego.lane_index[2]:
                speeds.append(abs(float(obs[0, 4])) * vy_range)   # the ego row's vy, as the shield reads it
            obs, _, terminated, truncated, _ = env.step(act(driver, obs, env.action_space))
            done = terminated or truncated
    env.close()
    assert len(speeds) > 20
    assert np.min(speeds) >= MID_CHANGE_VY
