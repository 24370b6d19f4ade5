"""SB3 models as black-box victims: same actions as SB3's own predict."""

from __future__ import annotations

import numpy as np
import pytest
from stable_baselines3 import DDPG, DQN

from zodrive.policies.victims import sb3_victim
from zodrive.envs import load_preset, make_env


@pytest.mark.parametrize("algo,preset", [(DQN, "discrete"), (DDPG, "continuous")])
def test_victim_acts_like_sb3_predict(algo, preset: str) -> None:
    env = make_env(load_preset(preset))
    model = algo("MlpPolicy", env, seed=0, device="cpu", learning_starts=10**9)
    victim = sb3_victim(model)
    obs = np.random.default_rng(0).uniform(-1, 1, size=(64, 5, 5)).astype(np.float32)
    predicted, _ = model.predict(obs, deterministic=True)
    ours = victim.actions(victim.query(obs))
    if preset == "discrete":
        np.testing.assert_array_equal(ours, predicted)
    else:
        np.testing.assert_allclose(ours, predicted, atol=1e-6)
    # the white-box path gives the same outputs as the query path
    import torch

    np.testing.assert_allclose(victim.differentiable(torch.from_numpy(obs)).detach().numpy(),
                               victim.query(obs), atol=1e-6)


def test_a_resumed_run_keeps_the_recipes_n_step_returns_or_says_so() -> None:
    """SB3 warns on a load that `n_steps` is ignored; `check_n_step_buffer` reads the buffer instead, and
    refuses a checkpoint whose buffer does not take the recipe's n-step returns (PPO's n_steps is a rollout)."""
    import gymnasium as gym
    from stable_baselines3 import PPO

    from zodrive.training.recipes import check_n_step_buffer
    from zodrive.errors import ZodriveError

    recipe = {"hyperparameters": {"n_steps": 30}}
    env = gym.make("CartPole-v1")
    check_n_step_buffer(DQN("MlpPolicy", env, n_steps=30, buffer_size=100, device="cpu"), recipe)
    with pytest.raises(ZodriveError, match="resumes with 1-step returns, the recipe says n_steps: 30"):
        check_n_step_buffer(DQN("MlpPolicy", env, buffer_size=100, device="cpu"), recipe)
    check_n_step_buffer(PPO("MlpPolicy", env, n_steps=64, batch_size=64, device="cpu"), {"hyperparameters": {"n_steps": 64}})
