"""Starting a DQN from a cloned network (issue 22, item 2): init, collection, calibration."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch as th
from stable_baselines3 import DQN

from zodrive.training.finetune import calibrate, collect, init_from_model
from zodrive.training.recipes import check_init
from zodrive.envs import load_preset, make_env
from zodrive.errors import ZodriveError


def _dqn(seed: int, arch: list[int], steps: int = 20, **kwargs) -> DQN:
    env = make_env(load_preset("discrete", [f"max_episode_steps={steps}"]))
    return DQN("MlpPolicy", env, seed=seed, device="cpu", policy_kwargs={"net_arch": arch}, **kwargs)


def test_init_loads_the_clone_into_the_online_and_the_target_network(tmp_path: Path) -> None:
    clone = _dqn(1, [16, 16])
    clone.save(tmp_path / "clone.zip")
    model = _dqn(2, [16, 16])
    assert not th.equal(model.q_net.q_net[0].weight, clone.q_net.q_net[0].weight)
    done = init_from_model(model, tmp_path / "clone.zip")
    assert len(done["sha256"]) == 64
    for net in (model.q_net, model.q_net_target):
        for (key, ours), theirs in zip(net.state_dict().items(), clone.q_net.state_dict().values()):
            assert th.equal(ours, theirs), key


def test_an_init_model_of_another_shape_is_a_one_line_error(tmp_path: Path) -> None:
    _dqn(1, [8]).save(tmp_path / "small.zip")
    with pytest.raises(ZodriveError) as info:
        init_from_model(_dqn(2, [16, 16]), tmp_path / "small.zip")
    assert "\n" not in str(info.value) and "small.zip" in str(info.value)
    _dqn(1, [16, 8]).save(tmp_path / "narrow.zip")
    with pytest.raises(ZodriveError, match=r"shape \(8, 16\)") as info:
        init_from_model(_dqn(2, [16, 16]), tmp_path / "narrow.zip")
    assert "\n" not in str(info.value)
    with pytest.raises(ZodriveError, match="not found"):
        init_from_model(_dqn(2, [16, 16]), tmp_path / "missing.zip")


def _fill(model: DQN, n: int, seed: int = 0) -> np.ndarray:
    """`n` synthetic transitions (episodes of 25 steps) whose reward depends on state and action."""
    rng = np.random.default_rng(seed)
    obs = rng.uniform(-1, 1, (n + 1, 5, 5)).astype(np.float32)
    for i in range(n):
        action = int(rng.integers(5))
        reward = 0.5 + 0.3 * obs[i, 0, 1] - 0.2 * (action == 4)
        done = (i + 1) % 25 == 0
        model.replay_buffer.add(obs[i][None], obs[i + 1][None], np.array([[action]]), np.array([reward]),
                                np.array([done]), [{"TimeLimit.truncated": False}])
    return obs


def test_calibration_changes_the_values_and_keeps_the_greedy_policy() -> None:
    model = _dqn(0, [32, 32], n_steps=5, gamma=0.99)
    obs = _fill(model, 400)
    fresh = th.as_tensor(np.random.default_rng(9).uniform(-1, 1, (300, 5, 5)), dtype=th.float32)
    states = th.cat([th.as_tensor(obs), fresh])
    with th.no_grad():
        before = model.q_net(states)
    stats = calibrate(model, ridge=1e-3, min_scale=0.1)
    with th.no_grad():
        after, target = model.q_net(states), model.q_net_target(states)
    assert th.equal(after.argmax(dim=1), before.argmax(dim=1))  # the clone's action at every state
    assert stats["greedy_agreement"] == 1.0 and stats["alpha"] >= 0.1
    assert float((after - before).abs().mean()) > 1.0  # values moved towards the returns (~0.5 / (1 - 0.99))
    assert th.equal(after, target)  # the target network starts from the calibrated one


def test_calibration_finds_the_value_of_a_constant_reward() -> None:
    """Reward 1 at every step, no termination, gamma 0.99: the policy's value is 100 everywhere."""
    model = _dqn(0, [32, 32], gamma=0.99)
    rng = np.random.default_rng(0)
    obs = rng.uniform(-1, 1, (501, 5, 5)).astype(np.float32)
    for i in range(500):
        model.replay_buffer.add(obs[i][None], obs[i + 1][None], np.array([[int(rng.integers(5))]]), np.array([1.0]),
                                np.array([False]), [{}])
    stats = calibrate(model, ridge=1e-6)
    assert stats["mean_q"] == pytest.approx(100.0, abs=2.0)
    assert stats["mean_abs_td_error_after"] < 0.1 * stats["mean_abs_td_error_before"]


def test_calibration_is_deterministic() -> None:
    outputs = []
    for _ in range(2):
        model = _dqn(0, [16, 16], n_steps=3)
        _fill(model, 100)
        calibrate(model)
        outputs.append(model.q_net.q_net[-1].weight.detach().clone())
    assert th.equal(*outputs)


def test_collect_drives_the_greedy_policy_into_the_buffer() -> None:
    model = _dqn(0, [16, 16], steps=15)
    env = make_env(load_preset("discrete", ["max_episode_steps=15"]))
    stats = collect(model, env, 2, seed=20_000, epsilon=0.0)
    n = stats["transitions"]
    assert stats["random_actions"] == 0 and 2 <= n <= 30 and n == model.replay_buffer.size()
    stored = th.as_tensor(model.replay_buffer.observations[:n, 0])
    with th.no_grad():
        greedy = model.q_net(stored).argmax(dim=1).numpy()
    np.testing.assert_array_equal(model.replay_buffer.actions[:n, 0, 0], greedy)


@pytest.mark.parametrize(("recipe", "message"), [
    ({"algo": "dqn", "calibrate": {}}, "calibrate needs init"),
    ({"algo": "dqn", "double_q": True, "init": "models/x"}, "without double_q"),
    ({"algo": "dqn", "init": 3}, "model path"),
    ({"algo": "dqn", "init": "m", "calibrate": {"episode": 3}}, "calibrate must be"),
    ({"algo": "dqn", "init": "m", "calibrate": {"epsilon": 2.0}}, "epsilon in"),
    ({"algo": "dqn", "init": "m", "guide": {"name": "rules", "pretrain_steps": 10}}, "not supported"),
])
def test_init_options_that_cannot_work_are_errors(recipe: dict, message: str) -> None:
    with pytest.raises(ZodriveError, match=message):
        check_init(recipe, "recipe 'x'")


def test_init_options_with_defaults() -> None:
    assert check_init({"algo": "dqn"}, "r") is None
    assert check_init({"algo": "dqn", "init": "m"}, "r") is None
    assert check_init({"algo": "dqn", "init": "m", "calibrate": {"episodes": 3}}, "r") == {
        "episodes": 3, "epsilon": 0.02, "ridge": 1e-3, "min_scale": 0.1, "td_steps": 0}


def test_td_policy_evaluation_keeps_the_greedy_policy_and_syncs_the_target() -> None:
    from stable_baselines3.common.logger import configure

    from zodrive.training.finetune import evaluate_td

    model = _dqn(0, [32, 32], n_steps=3, gamma=0.9, learning_rate=1e-3)
    model.set_logger(configure(None, []))
    obs = _fill(model, 300)
    calibrate(model)
    x = th.as_tensor(obs)
    with th.no_grad():
        before = model.q_net(x)
    stats = evaluate_td(model, 1000, 32, margin=0.8, weight=1.0, sync_every=100)
    with th.no_grad():
        after = model.q_net(x)
    assert stats["greedy_agreement"] > 0.9 and float((after.argmax(1) == before.argmax(1)).float().mean()) > 0.9
    assert stats["td_loss_last"] < stats["td_loss_first"]
    for online, target in zip(model.q_net.parameters(), model.q_net_target.parameters()):
        assert th.equal(online, target)
