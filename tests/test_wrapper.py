"""The attack wrapper: gymnasium-conformant, touches only what the policy sees, works in SB3."""

from __future__ import annotations

import numpy as np
from gymnasium.utils.env_checker import check_env

from toys import linear_victim
from zodrive.attacks import AttackSpec
from zodrive.envs import load_preset, make_env
from zodrive.wrappers import AttackWrapper, make_attacked_env

PRESET = load_preset("discrete")


def _wrapped(steps: int = 5) -> AttackWrapper:
    return make_attacked_env(PRESET, linear_victim(), AttackSpec(steps=steps, n_directions=4))


def test_wrapper_passes_gymnasium_env_checker() -> None:
    check_env(_wrapped(), skip_render_check=True)


def test_wrapper_changes_the_observation_not_the_simulator() -> None:
    attacked, clean = _wrapped(), make_env(PRESET)
    obs_a, info = attacked.reset(seed=4)
    obs_c, _ = clean.reset(seed=4)
    np.testing.assert_array_equal(info["clean_obs"], obs_c)
    assert np.abs(obs_a - obs_c).max() <= 0.2 + 1e-6
    for action in [1, 4, 1, 4, 1]:
        obs_a, r_a, *_ , info = attacked.step(action)
        obs_c, r_c, *_ = clean.step(action)
        assert r_a == r_c  # same simulator, same actions: same rewards
        np.testing.assert_array_equal(info["clean_obs"], obs_c)
        assert {"queries", "iterations", "success", "linf", "l2"} <= set(info["attack"])
        assert attacked.last_wall_time > 0
