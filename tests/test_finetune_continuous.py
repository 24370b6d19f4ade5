"""Starting a TD3 / DDPG from a cloned actor (issue 22, item 2): init, critic evaluation, TD3+BC."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch as th
from stable_baselines3 import DDPG, DQN, TD3
from stable_baselines3.common.logger import configure

from zodrive.training.actor_critic_variants import GuidedDDPG, GuidedTD3
from zodrive.training.finetune import collect, evaluate_critic, init_actor_from_model
from zodrive.training.recipes import algorithm_class, check_init
from zodrive.envs import load_preset, make_env
from zodrive.errors import ZodriveError


def _env(steps: int = 20):
    return make_env(load_preset("continuous", [f"max_episode_steps={steps}"]))


def _td3(seed: int, arch: list[int], cls: type = TD3, **kwargs) -> TD3:
    model = cls("MlpPolicy", _env(), seed=seed, device="cpu", policy_kwargs={"net_arch": arch}, **kwargs)
    model.set_logger(configure(None, []))
    return model


def _fill(model: TD3, n: int, reward: float) -> np.ndarray:
    """`n` transitions between uniform random states with random actions and a constant reward,
    no termination; returns the n + 1 states."""
    rng = np.random.default_rng(0)
    obs = rng.uniform(-1, 1, (n + 1, 5, 5)).astype(np.float32)
    for i in range(n):
        model.replay_buffer.add(obs[i][None], obs[i + 1][None], rng.uniform(-1, 1, (1, 2)), np.array([reward]),
                                np.array([False]), [{}])
    return obs


def test_init_loads_the_actor_into_the_actor_and_the_target_actor_only(tmp_path: Path) -> None:
    clone = _td3(1, [16, 16], cls=DDPG)  # a DDPG actor goes into a TD3: the same actor layout
    clone.save(tmp_path / "clone.zip")
    model = _td3(2, [16, 16])
    critic = {k: v.clone() for k, v in model.critic.state_dict().items()}
    done = init_actor_from_model(model, tmp_path / "clone.zip")
    assert done["part"] == "actor" and len(done["sha256"]) == 64
    for net in (model.actor, model.actor_target):
        for (key, ours), theirs in zip(net.state_dict().items(), clone.actor.state_dict().values()):
            assert th.equal(ours, theirs), key
    for key, value in model.critic.state_dict().items():
        assert th.equal(value, critic[key]), key  # the critics stay the recipe's own


def test_an_init_model_that_is_not_an_actor_or_has_another_shape_is_a_one_line_error(tmp_path: Path) -> None:
    DQN("MlpPolicy", make_env(load_preset("discrete", ["max_episode_steps=5"])), device="cpu").save(tmp_path / "dqn.zip")
    with pytest.raises(ZodriveError, match="not a DDPG or TD3") as info:
        init_actor_from_model(_td3(0, [16, 16]), tmp_path / "dqn.zip")
    assert "\n" not in str(info.value)
    _td3(1, [16, 8]).save(tmp_path / "narrow.zip")
    with pytest.raises(ZodriveError, match="shape") as info:
        init_actor_from_model(_td3(0, [16, 16]), tmp_path / "narrow.zip")
    assert "\n" not in str(info.value)


def test_collect_drives_the_actor_with_its_exploration_noise_into_the_buffer() -> None:
    model = _td3(0, [16, 16])
    stats = collect(model, _env(15), 2, seed=20_000)
    n = stats["transitions"]
    assert "epsilon" not in stats and 2 <= n <= 30 and n == model.replay_buffer.size()
    stored = th.as_tensor(model.replay_buffer.observations[:n, 0])
    with th.no_grad():
        np.testing.assert_allclose(model.replay_buffer.actions[:n, 0], model.actor(stored).numpy(), atol=1e-6)


def test_critic_evaluation_finds_the_value_of_a_constant_reward_and_leaves_the_actor_alone() -> None:
    """Reward 1 at every step, no termination, gamma 0.5: the actor's value is 2 everywhere."""
    model = _td3(0, [32, 32], cls=GuidedTD3, gamma=0.5, batch_size=64)
    _fill(model, 500, reward=1.0)
    actor = {k: v.clone() for k, v in model.actor.state_dict().items()}
    stats = evaluate_critic(model, 2000, 64)
    assert stats["mean_q"] == pytest.approx(2.0, abs=0.1)
    assert stats["td_loss_after"] < 0.1 * stats["td_loss_before"]
    for key, value in model.actor.state_dict().items():
        assert th.equal(value, actor[key]), key
    assert model.train_actor and model.tau == 0.005  # restored for RL


@pytest.mark.parametrize(("cls", "error"), [(GuidedTD3, "squared"), (GuidedDDPG, "squared"), (GuidedTD3, "absolute")])
def test_the_imitation_term_pulls_the_actor_to_the_guide(cls: type, error: str) -> None:
    """With a large imitation weight, a few hundred updates bring the actor to a guide's constant action."""
    model = _td3(0, [32, 32], cls=cls, batch_size=64, learning_rate=3e-3)
    target = np.array([0.5, -0.3], dtype=np.float32)
    model.configure_guide(lambda batch: np.tile(target, (len(batch), 1)), imitation=100.0, error=error)
    obs = _fill(model, 300, reward=0.0)
    model.train(600, 64)
    with th.no_grad():
        actions = model.actor(th.as_tensor(obs)).numpy()
    np.testing.assert_allclose(actions.mean(axis=0), target, atol=0.05)


@pytest.mark.parametrize(("recipe", "message"), [
    ({"algo": "td3", "init": "m", "calibrate": {"epsilon": 0.1}}, "calibrate must be"),
    ({"algo": "ddpg", "init": "m", "calibrate": {"ridge": 0.1}}, "calibrate must be"),
    ({"algo": "td3", "init": "m", "calibrate": {"td_steps": 2.5}}, "integers"),
    ({"algo": "td3", "init": "m", "calibrate": {"episodes": True}}, "numbers"),
    ({"algo": "td3", "calibrate": {"td_steps": 5}}, "calibrate needs init"),
])
def test_actor_critic_init_options_that_cannot_work_are_errors(recipe: dict, message: str) -> None:
    with pytest.raises(ZodriveError, match=message):
        check_init(recipe, "recipe 'x'")


def test_actor_critic_init_options_with_defaults() -> None:
    assert check_init({"algo": "td3", "init": "m", "calibrate": {"episodes": 3}}, "r") == {"episodes": 3,
                                                                                          "td_steps": 10000}
    assert algorithm_class({"algo": "td3", "guide": {"name": "rules"}}) is GuidedTD3
    assert algorithm_class({"algo": "ddpg", "guide": {"name": "rules"}}) is GuidedDDPG


@pytest.mark.parametrize("guide", [{"name": "rules", "start": 0.5}, {"name": "rules", "margin": 0.8},
                                   {"name": "idm", "imitation": 0.4}, {"name": "rules", "imitation": -1},
                                   {"name": "rules", "imitation": "0.4"}, {"name": "rules", "error": "huber"}])
def test_a_guide_option_an_actor_critic_would_ignore_is_an_error(guide: dict, tmp_path: Path) -> None:
    from zodrive.training.recipes import load_recipe, train

    recipe = {**load_recipe("td3"), "guide": guide, "total_timesteps": 10}
    with pytest.raises(ZodriveError, match="guide") as info:
        train(recipe, tmp_path / "run", progress_bar=False)
    assert "\n" not in str(info.value)


def test_the_init_guide_is_the_init_model_s_actor_frozen(tmp_path: Path) -> None:
    from zodrive.training.finetune import frozen_actor

    clone = _td3(1, [16, 16])
    clone.save(tmp_path / "clone.zip")
    model = _td3(2, [16, 16])
    guide = frozen_actor(model, tmp_path / "clone.zip")
    obs = np.random.default_rng(0).uniform(-1, 1, (7, 5, 5)).astype(np.float32)
    with th.no_grad():
        np.testing.assert_array_equal(guide(obs), clone.actor(th.as_tensor(obs)).numpy())
    model.actor.mu[0].weight.data.add_(1.0)  # the learner moves; the guide does not
    with th.no_grad():
        np.testing.assert_array_equal(guide(obs), clone.actor(th.as_tensor(obs)).numpy())


def test_the_init_guide_needs_an_init_model(tmp_path: Path) -> None:
    from zodrive.training.recipes import load_recipe, train

    recipe = {**load_recipe("td3"), "guide": {"name": "init"}, "total_timesteps": 10}
    with pytest.raises(ZodriveError, match="needs init") as info:
        train(recipe, tmp_path / "run", progress_bar=False)
    assert "\n" not in str(info.value) and not (tmp_path / "run").exists()  # no half-made run folder


def test_an_actor_critic_started_from_a_clone_without_a_guide_still_evaluates_its_critic_only() -> None:
    """`init` without `guide` on a TD3/DDPG recipe trains a GuidedTD3 (TD3's own loss without a guide),
    so the critic-only calibration really leaves the actor alone."""
    assert algorithm_class({"algo": "td3", "init": "m"}) is GuidedTD3
    assert algorithm_class({"algo": "ddpg", "init": "m"}) is GuidedDDPG
    assert algorithm_class({"algo": "td3"}) is TD3
    model = _td3(0, [16, 16], cls=GuidedTD3, batch_size=32)
    _fill(model, 100, reward=1.0)
    actor = {k: v.clone() for k, v in model.actor.state_dict().items()}
    evaluate_critic(model, 20, 32)
    for key, value in model.actor.state_dict().items():
        assert th.equal(value, actor[key]), key
    model.train(20, 32)  # with the actor on, TD3's loss moves it
    assert any(not th.equal(value, actor[key]) for key, value in model.actor.state_dict().items())
