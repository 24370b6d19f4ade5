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


def test_a_guided_dqn_collects_the_guides_actions_then_its_own() -> None:
    from zodrive.training.dqn_variants import GuidedDQN

    env = make_env(load_preset("discrete", ["max_episode_steps=30"]))
    model = GuidedDQN("MlpPolicy", env, learning_starts=10, buffer_size=500, seed=0, device="cpu")
    calls: list[int] = []

    def guide(obs: np.ndarray) -> np.ndarray:
        calls.append(model.num_timesteps)
        return np.full(len(obs), 2)

    model.configure_guide(guide, start=1.0, steps=60)
    model.learn(90)
    early = model.replay_buffer.actions[:20, 0, 0]
    assert np.mean(early == 2) > 0.6  # guide rate 1 -> 0.67 over these steps, uniform otherwise
    assert calls and max(calls) < 60 and model.guide_rate() == 0.0  # gone once its rate reaches 0


def test_the_imitation_margin_pulls_the_greedy_action_to_the_guides() -> None:
    import torch as th

    from zodrive.training.dqn_variants import GuidedDQN

    env = make_env(load_preset("discrete", ["max_episode_steps=30"]))
    model = GuidedDQN("MlpPolicy", env, seed=0, device="cpu")
    guide = lambda obs: (np.abs(obs).reshape(len(obs), -1).sum(axis=1) * 10).astype(int) % 5  # noqa: E731
    model.configure_guide(guide, start=0.0, steps=1, imitation=1.0, margin=0.8)
    obs = th.as_tensor(np.random.default_rng(0).uniform(-1, 1, (64, 5, 5)), dtype=th.float32)
    first = model.extra_loss(obs)
    assert first is not None and first.item() >= 0
    opt = th.optim.Adam(model.q_net.parameters(), lr=1e-2)
    for _ in range(300):
        loss = model.extra_loss(obs)
        opt.zero_grad()
        loss.backward()
        opt.step()
    taken = model.q_net(obs).argmax(dim=1).numpy()
    assert np.mean(taken == guide(obs.numpy())) > 0.9 and model.extra_loss(obs).item() < first.item()


def test_demonstrations_fill_the_buffer_and_pretraining_learns_them() -> None:
    """DQfD's start: the guide's episodes go into the replay buffer as they were driven, and the
    pre-training updates (TD + margin) move the greedy action towards the guide's on them."""
    import torch as th

    from zodrive.training.dqn_variants import GuidedDQN
    from zodrive.drivers.rules import ObservationRules

    preset = load_preset("discrete", ["max_episode_steps=40"])
    model = GuidedDQN("MlpPolicy", make_env(preset), seed=0, device="cpu", batch_size=32, n_steps=5, learning_rate=1e-3,
                      policy_kwargs={"net_arch": [64, 64]})
    rules = ObservationRules(preset)
    model.configure_guide(rules.actions, start=0.0, steps=1, imitation=1.0, margin=0.8)
    stats = model.add_demonstrations(make_env(preset), 2, seed=20_000)
    buffer = model.replay_buffer
    assert stats["episodes"] == 2 and stats["transitions"] == buffer.size() == 80
    stored = buffer.observations[:80, 0]
    np.testing.assert_array_equal(buffer.actions[:80, 0, 0], rules.actions(stored))  # the guide's own actions
    assert buffer.dones[39, 0] == 1 and buffer.dones[:39, 0].sum() == 0  # episode ends where it ended
    x = th.as_tensor(stored, dtype=th.float32)

    def agreement() -> float:
        return float(np.mean(model.q_net(x).argmax(dim=1).numpy() == rules.actions(stored)))

    from stable_baselines3.common.logger import configure

    model.set_logger(configure(None, []))
    before = agreement()
    model.pretrain(600, 32, sync_every=200)
    assert agreement() > max(before, 0.8)
    for online, target in zip(model.q_net.parameters(), model.q_net_target.parameters()):
        assert th.equal(online, target)  # the target network copied the pre-trained one


def test_recipe_guide_names_the_rules_it_follows() -> None:
    """`guide: {name: close-rules}` gives the DQN the close rules' decisions, not the rules'; an
    unknown name is a one-line error."""
    from zodrive.drivers.rules import named_rules
    from zodrive.training.recipes import _configure_guide
    from zodrive.errors import ZodriveError

    preset = load_preset("discrete")

    class Recorder:
        def configure_guide(self, guide, start, steps, **kwargs):
            self.guide = guide

    close, plain = named_rules(preset, "close-rules"), named_rules(preset, "rules")
    states = np.random.default_rng(1).uniform(-1, 1, size=(2000, 5, 5)).astype(np.float32)
    states[:, :, 0] = 1.0  # every vehicle present
    assert (close.actions(states) != plain.actions(states)).any()  # the two guides tell apart on these states
    model = Recorder()
    _configure_guide(model, {"algo": "dqn", "total_timesteps": 100, "guide": {"name": "close-rules"}}, preset)
    np.testing.assert_array_equal(model.guide(states), close.actions(states))
    with pytest.raises(ZodriveError, match="recipe guide must be"):
        _configure_guide(model, {"algo": "dqn", "total_timesteps": 100, "guide": {"name": "closer-rules"}}, preset)


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
