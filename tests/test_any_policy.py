"""Any SB3 / sb3-contrib MLP policy is read without unpickling and acts as SB3 does.

For every algorithm the safe loader rebuilds the acting network from plain data; its
action on 200 states equals SB3's own `predict(deterministic=True)`, and SB3's full loader
(`--trust-model`) gives the very same outputs.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

sb3_contrib = pytest.importorskip("sb3_contrib")
from stable_baselines3 import A2C, DDPG, DQN, PPO, SAC, TD3  # noqa: E402

from zodrive.policies.loading import load_model  # noqa: E402
from zodrive.policies.safe_load import load_policy_network  # noqa: E402
from zodrive.policies.victims import network_victim, sb3_victim  # noqa: E402
from zodrive.cli import main  # noqa: E402
from zodrive.errors import ZodriveError  # noqa: E402

SMALL = {"buffer_size": 1000, "learning_starts": 50}
ALGOS = {  # name -> (class, constructor options); the policies are SB3's defaults unless said
    "dqn": (DQN, SMALL),
    "qrdqn": (sb3_contrib.QRDQN, {**SMALL, "policy_kwargs": {"n_quantiles": 7}}),
    "ddpg": (DDPG, SMALL),
    "td3": (TD3, SMALL),
    "sac": (SAC, SMALL),
    "tqc": (sb3_contrib.TQC, SMALL),
    "ppo": (PPO, {"n_steps": 64, "batch_size": 32}),
    "a2c": (A2C, {}),
    "ppo-relu": (PPO, {"n_steps": 64, "batch_size": 32,
                       "policy_kwargs": {"activation_fn": torch.nn.ReLU, "net_arch": {"pi": [32, 16], "vf": [8]}}}),
}
CONTINUOUS = {"ddpg", "td3", "sac", "tqc"}


def _saved(tmp_path: Path, algo: str, env_id: str, steps: int = 100) -> tuple[Path, object]:
    cls, options = ALGOS[algo]
    model = cls("MlpPolicy", gym.make(env_id), seed=0, device="cpu", **options).learn(steps)
    path = tmp_path / f"{algo}.zip"
    model.save(path)
    return path, model


def _states(env_id: str, n: int = 200) -> np.ndarray:
    env = gym.make(env_id)
    env.observation_space.seed(0)
    return np.stack([env.observation_space.sample() for _ in range(n)]).clip(-10, 10).astype(np.float32)


ENVS = [(a, "CartPole-v1") for a in ALGOS if a not in CONTINUOUS] + \
       [(a, env) for a in sorted(CONTINUOUS | {"ppo", "a2c"}) for env in ("Pendulum-v1", "MountainCarContinuous-v0")
        if not (a in ("ppo", "a2c") and env == "MountainCarContinuous-v0")]


@pytest.mark.parametrize("algo,env_id", ENVS)
def test_the_safe_victim_acts_as_sb3_predicts(tmp_path: Path, algo: str, env_id: str) -> None:
    path, model = _saved(tmp_path, algo, env_id)
    network = load_policy_network(path)
    safe = network_victim(network.net, network.kind, network.obs_shape)
    states = _states(env_id)
    predicted, _ = model.predict(states, deterministic=True)
    actions = safe.actions(safe.query(states))
    if network.kind == "discrete":
        np.testing.assert_array_equal(actions, predicted)
    else:  # [-1, 1] spaces skip SB3's identity rescaling, which can move the last bit
        exact = not np.all(model.action_space.high == 1.0)
        np.testing.assert_allclose(actions, predicted.reshape(actions.shape), rtol=0, atol=0 if exact else 1e-6)
    trusted = sb3_victim(load_model(path, trust=True))  # SB3's loader: the very same outputs
    np.testing.assert_array_equal(safe.query(states), trusted.query(states))


def test_a_recurrent_policy_is_refused_in_one_line(tmp_path: Path) -> None:
    model = sb3_contrib.RecurrentPPO("MlpLstmPolicy", gym.make("CartPole-v1"), n_steps=16, batch_size=16, seed=0)
    model.save(tmp_path / "rppo")
    with pytest.raises(ZodriveError, match="recurrent"):
        load_policy_network(tmp_path / "rppo.zip")


def test_an_unknown_activation_and_a_feature_extractor_are_refused(tmp_path: Path) -> None:
    path, _ = _saved(tmp_path, "ppo-relu", "CartPole-v1", steps=64)
    with zipfile.ZipFile(path) as src:
        data = json.loads(src.read("data"))
        members = {n: src.read(n) for n in src.namelist()}
    for key, value, message in (("activation_fn", "<class 'my.module.Swish'>", "activation"),
                                ("features_extractor_class", "<class 'my.module.Cnn'>", "features_extractor_class")):
        crafted = tmp_path / f"crafted-{key}.zip"
        changed = {**data, "policy_kwargs": {**data["policy_kwargs"], key: value}}
        with zipfile.ZipFile(crafted, "w") as dst:
            for name, raw in members.items():
                dst.writestr(name, json.dumps(changed) if name == "data" else raw)
        with pytest.raises(ZodriveError, match=message):
            load_policy_network(crafted)


def test_a_ppo_saved_by_plain_sb3_is_evaluated_and_attacked(tmp_path: Path, capsys) -> None:
    from zodrive.envs import load_preset, make_env

    preset = load_preset("highway-fast", ["highway.vehicles_count=5"])
    model = PPO("MlpPolicy", make_env(preset), n_steps=32, batch_size=32, seed=0, device="cpu").learn(32)
    model.save(tmp_path / "ppo")
    code = main(["evaluate", str(tmp_path / "ppo.zip"), "--preset", "highway-fast", "--env-set",
                 "highway.vehicles_count=5", "--episodes", "1", "--attack", "random-search", "--eps", "0.05",
                 "--target", "none", "--steps", "3", "--out", str(tmp_path / "eval"), "--no-progress"])
    assert code == 0, capsys.readouterr().err
    summary = json.loads((tmp_path / "eval" / "summary.json").read_text())
    assert summary["preset"] == "highway-fast" and summary["max_linf"] <= 0.05 + 1e-6
    assert summary["queries_per_step"] > 0


@pytest.mark.parametrize("algo,env_id", [("dqn", "CartPole-v1"), ("sac", "Pendulum-v1")])
def test_any_gymnasium_environment_by_id(tmp_path: Path, algo: str, env_id: str, capsys) -> None:
    path, _ = _saved(tmp_path, algo, env_id)
    out = tmp_path / "eval"
    assert main(["evaluate", str(path), "--env-id", env_id, "--episodes", "1",
                 "--attack", "random-search", "--target", "none", "--eps", "0.1", "--steps", "3",
                 "--out", str(out), "--no-progress"]) == 0, capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["preset"] == env_id and summary["max_linf"] <= 0.1 + 1e-6 and summary["queries_per_step"] > 1
    printed = capsys.readouterr().out
    assert "m/s" not in printed  # no driving metrics off a highway-env road


def test_the_api_refuses_what_zodrive_cannot_query_in_its_own_words(tmp_path) -> None:
    """A recurrent policy, a Dict observation and stacked frames: refused in one line that names the reason
    (the CLI refuses the same zips), never a shape error from torch or a wrong Result."""
    import gymnasium as gym
    import highway_env  # noqa: F401
    from sb3_contrib import RecurrentPPO
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecFrameStack

    import zodrive
    from zodrive.cli import main
    from zodrive.errors import ZodriveError

    lstm = RecurrentPPO("MlpLstmPolicy", "CartPole-v1", n_steps=32, seed=0, device="cpu",
                        policy_kwargs={"lstm_hidden_size": 25})
    with pytest.raises(ZodriveError, match="recurrent policies are not supported"):
        zodrive.evaluate(lstm, env_id="CartPole-v1", episodes=1)
    parking = PPO("MultiInputPolicy", gym.make("parking-v0"), n_steps=32, seed=0, device="cpu")
    with pytest.raises(ZodriveError, match="observes a Dict"):
        zodrive.evaluate(parking, env_id="CartPole-v1", episodes=1)
    parking.save(tmp_path / "parking.zip")
    assert main(["evaluate", str(tmp_path / "parking.zip"), "--env-id", "CartPole-v1", "--episodes", "1"]) == 2
    stacked = PPO("MlpPolicy", VecFrameStack(DummyVecEnv([lambda: gym.make("CartPole-v1")]), 4), n_steps=32, seed=0,
                  device="cpu")
    with pytest.raises(ZodriveError, match="4 stacked frames"):
        zodrive.evaluate(stacked, env_id="CartPole-v1", episodes=1)
    stacked.save(tmp_path / "stacked.zip")  # the zip alone: its shape says 4 times as long
    with pytest.raises(ZodriveError, match="4 times as long on axis 0: trained on 4 stacked frames"):
        zodrive.evaluate(str(tmp_path / "stacked.zip"), env_id="CartPole-v1", episodes=1)
