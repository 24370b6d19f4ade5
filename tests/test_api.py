"""The Python API: `zodrive.evaluate`, `zodrive.attack` and `zodrive.AttackWrapper` on a model
trained in the same session (CartPole: fast, and a scenario with no FASTER action)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3 import DQN

import zodrive
from zodrive.errors import ZodriveError


@pytest.fixture(scope="module")
def model() -> DQN:
    torch.manual_seed(0)
    return DQN("MlpPolicy", gym.make("CartPole-v1"), learning_starts=50, seed=0, device="cpu").learn(300)


def own_loop(model: DQN, seeds: range) -> list[float]:
    """What a user's own evaluation loop gives: deterministic actions from `model.predict`."""
    env, returns = gym.make("CartPole-v1"), []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        done, total = False, 0.0
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, reward, terminated, truncated, _ = env.step(int(action))
            total, done = total + reward, terminated or truncated
        returns.append(total)
    return returns


def test_evaluate_an_in_memory_model_gives_the_users_own_numbers(model: DQN) -> None:
    result = zodrive.evaluate(model, env_id="CartPole-v1", episodes=3, seed=7)
    assert [r["return"] for r in result.episodes] == own_loop(model, range(7, 10))
    assert result.summary["episodes"] == 3 and result.summary["attack"] is None
    assert result.summary["mean_return"] == pytest.approx(np.mean(own_loop(model, range(7, 10))))
    assert "dqn" in repr(result)


def test_evaluate_under_attack_is_untargeted_where_there_is_no_faster(model: DQN, tmp_path) -> None:
    result = zodrive.evaluate(model, env_id="CartPole-v1", attack="random-search", eps=0.05, steps=5,
                              episodes=2, seed=7, envs=2)
    assert result.summary["attack"] == "random-search" and result.summary["target"] == "none"
    assert result.summary["queries_per_step"] > 0 and result.summary["max_linf"] <= 0.05 + 1e-6
    ax = result.plot(tmp_path / "returns.png")
    assert (tmp_path / "returns.png").stat().st_size > 0 and len(ax.patches) >= 2


def test_attack_a_batch_stays_in_the_ball(model: DQN) -> None:
    obs = np.random.default_rng(0).uniform(-0.05, 0.05, size=(4, 4)).astype(np.float32)
    result = zodrive.attack(model, obs, env_id="CartPole-v1", attack="random-search", eps=0.05, steps=10)
    assert result.x_adv.shape == obs.shape
    assert np.abs(result.x_adv - obs).max() <= 0.05 + 1e-6
    assert (result.queries > 0).all()


def test_the_wrapper_reads_the_environment(model: DQN) -> None:
    env = zodrive.AttackWrapper(gym.make("CartPole-v1"), model, attack="random-search", eps=0.05, steps=5)
    obs, info = env.reset(seed=3)
    for _ in range(5):
        assert np.abs(obs - info["clean_obs"]).max() <= 0.05 + 1e-6
        obs, _, terminated, truncated, info = env.step(int(model.predict(obs, deterministic=True)[0]))
        assert info["attack"]["queries"] > 0
        if terminated or truncated:
            break


def test_the_wrapper_is_the_engines_and_gymnasium_rebuilds_it(model: DQN) -> None:
    from gymnasium.utils.env_checker import check_env

    from zodrive.system import AttackWrapper

    assert zodrive.AttackWrapper is AttackWrapper  # one class: the engine builds it with from_attacker
    env = zodrive.AttackWrapper(gym.make("CartPole-v1"), model, attack="random-search", eps=0.05, steps=5)
    check_env(env, skip_render_check=True)  # rebuilds it from env.spec: the user's own arguments
    again = env.spec.make()
    assert isinstance(again, AttackWrapper) and again.oracle is not env.oracle
    np.testing.assert_array_equal(again.reset(seed=3)[0], env.reset(seed=3)[0])  # the same attack, built anew
    with pytest.raises(ZodriveError, match="already queries its victim"):
        zodrive.AttackWrapper(gym.make("CartPole-v1"), model, env.attacker)
    with pytest.raises(ZodriveError, match="already queries its victim"):
        zodrive.AttackWrapper(gym.make("CartPole-v1"), None, env.attacker, eps=0.1)


def test_the_api_refuses_in_one_line(model: DQN, tmp_path) -> None:
    model.save(tmp_path / "m")
    with pytest.raises(ZodriveError, match="holds no environment .* say where it drives"):
        zodrive.evaluate(DQN.load(tmp_path / "m.zip", device="cpu"))  # loaded without env=: nothing says where
    with pytest.raises(ZodriveError, match="environment Pendulum-v1, not CartPole-v1"):
        zodrive.evaluate(model, env_id="Pendulum-v1")  # the CartPole it holds says where it was trained
    with pytest.raises(ZodriveError, match="without an attack"):
        zodrive.evaluate(model, env_id="CartPole-v1", eps=0.05)
    with pytest.raises(ZodriveError, match="in memory"):
        zodrive.evaluate(model, env_id="CartPole-v1", out="somewhere")
    with pytest.raises(ZodriveError, match="cannot read a policy"):
        zodrive.evaluate(42, env_id="CartPole-v1")
    for bad in ({"episodes": 10**12}, {"seed": -1}, {"episodes": 2.5}, {"envs": 0}):  # refused before any allocation
        with pytest.raises(ZodriveError, match="must be an integer in"):
            zodrive.evaluate("baseline:slower", "highway-fast", **bad)
    with pytest.raises(ZodriveError, match="trust_model applies to stable-baselines3 zips"):
        zodrive.evaluate("baseline:slower", "highway-fast", trust_model=True)  # the CLI refuses --trust-model too
    with pytest.raises(ZodriveError, match="wraps a gymnasium environment, not a NoneType"):
        zodrive.AttackWrapper(None, model)


class Logger:
    """A numpy victim that logs every row it receives."""

    def __init__(self) -> None:
        self.rows = 0
        self.weights = np.random.default_rng(0).normal(size=(4, 2)).astype(np.float32)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        self.rows += len(obs)
        return obs.reshape(len(obs), -1) @ self.weights


@pytest.mark.parametrize("attack", ["random-search", "zo-signsgd"])
def test_the_victim_sees_exactly_the_rows_reported(attack: str) -> None:
    seen, reported, returns = [], [], []
    for envs in (1, 4):
        victim = Logger()
        result = zodrive.evaluate(victim, env_id="CartPole-v1", attack=attack, eps=0.05, steps=4, episodes=4,
                                  seed=11, envs=envs)
        rows = result.summary["victim_rows"]
        seen.append(victim.rows)
        reported.append(rows["attack_queries"] + rows["decisions"])
        returns.append([r["return"] for r in result.episodes])
    assert seen == reported and seen[0] == seen[1] and returns[0] == returns[1]


def test_a_policy_file_sees_only_what_is_reported(tmp_path) -> None:
    log = tmp_path / "rows.txt"
    (tmp_path / "victim.py").write_text(
        "import numpy as np\n"
        "def make():\n"
        "    w = np.random.default_rng(0).normal(size=(4, 2)).astype(np.float32)\n"
        "    def policy(obs):\n"
        f"        with open({str(log)!r}, 'a') as f: f.write(f'{{len(obs)}}\\n')\n"
        "        return obs.reshape(len(obs), -1) @ w\n"
        "    return policy\n")
    result = zodrive.evaluate(f"{tmp_path / 'victim.py'}:make", env_id="CartPole-v1", attack="random-search",
                              eps=0.05, steps=4, episodes=3, seed=11, envs=3)
    rows = result.summary["victim_rows"]
    assert sum(map(int, log.read_text().split())) == rows["attack_queries"] + rows["decisions"]


def test_a_callable_that_returns_actions_is_a_victim() -> None:
    def act(obs: np.ndarray) -> np.ndarray:  # discrete actions, not scores
        return (obs.reshape(len(obs), -1)[:, 2] > 0).astype(int)

    result = zodrive.evaluate(act, env_id="CartPole-v1", episodes=2, seed=5)
    env, returns = gym.make("CartPole-v1"), []
    for seed in (5, 6):
        obs, _ = env.reset(seed=seed)
        done, total = False, 0.0
        while not done:
            obs, reward, terminated, truncated, _ = env.step(int(act(obs[None])[0]))
            total, done = total + reward, terminated or truncated
        returns.append(total)
    assert [r["return"] for r in result.episodes] == returns
    with pytest.raises(ZodriveError, match="not action indices 0..1"):
        zodrive.evaluate(lambda obs: np.full(len(obs), 7), env_id="CartPole-v1", episodes=1)


def test_export_says_what_it_exports(tmp_path) -> None:
    from zodrive.cli import main

    (tmp_path / "p.py").write_text("def make():\n    return lambda obs: obs\n")
    assert main(["export", f"{tmp_path / 'p.py'}:make", "--out", str(tmp_path / "m.onnx")]) == 2


def test_the_progress_bar_moves_within_an_episode(capsys) -> None:
    """Bars sat at 0 % through long episodes and filled in one burst: the bar counts environment steps."""
    from zodrive.envs import load_preset

    zodrive.evaluate("baseline:rules", load_preset("discrete", ["max_episode_steps=40"]), episodes=1, envs=1,
                     progress=True)
    err = capsys.readouterr().err.replace("\r", "\n")
    assert "0/1" in err and "steps=1" in err  # drawn with the first step, long before the episode's end
