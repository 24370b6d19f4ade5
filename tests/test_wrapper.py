"""The attack wrapper: gymnasium-conformant, touches only what the policy sees, works in SB3."""

from __future__ import annotations

import numpy as np
from gymnasium.utils.env_checker import check_env

from toys import linear_victim
from zodrive.attacks import AttackSpec
from zodrive.envs import load_preset, make_env
from zodrive.system import AttackWrapper, make_attacked_env

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
        # what the policy is fed is the attack's point, not the clean observation
        assert np.abs(obs_a - obs_c).max() == np.float32(info["attack"]["linf"]) <= 0.2 + 1e-6


def test_the_policy_is_fed_the_perturbation_that_flips_it() -> None:
    victim = linear_victim()
    attacked = make_attacked_env(PRESET, victim, AttackSpec(attack="random-search", steps=30, n_directions=10,
                                                            target="none", eps=0.2))
    obs, info = attacked.reset(seed=4)
    flipped = 0
    for _ in range(8):
        fed, truth = victim.query(obs[None])[0].argmax(), victim.query(info["clean_obs"][None])[0].argmax()
        assert (fed != truth) == info["attack"]["success"]  # it acts otherwise exactly where the attack says so
        flipped += int(fed != truth)
        obs, *_, info = attacked.step(1)
    assert flipped > 0
