"""ONNX victims: the exported network answers like the SB3 policy, attacked episodes match."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnxruntime")

from zodrive.policies.onnx_policy import onnx_victim  # noqa: E402
from zodrive.policies.resolve import load_victim  # noqa: E402
from zodrive.cli import main  # noqa: E402
from zodrive.envs import load_preset  # noqa: E402


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("onnx") / "dqn.onnx"
    assert main(["export", "models/dqn", "--out", str(out)]) == 0
    return out


def test_onnx_outputs_equal_the_sb3_policy(exported: Path) -> None:
    preset = load_preset("discrete")
    reference = load_victim("models/dqn", preset)
    victim = onnx_victim(exported)
    assert victim.kind == "discrete" and victim.obs_shape == (5, 5)
    x = np.random.default_rng(0).uniform(-1, 1, (64, 5, 5)).astype(np.float32)
    expected = reference.query(x)
    np.testing.assert_allclose(victim.query(x), expected, rtol=1e-5, atol=1e-5 * np.abs(expected).max())


def test_an_attacked_episode_gives_the_same_numbers_through_both(exported: Path, tmp_path: Path) -> None:
    args = ["--episodes", "1", "--no-progress", "--attack", "random-search", "--steps", "10",
            "--env-set", "max_episode_steps=40"]
    assert main(["evaluate", "models/dqn", "--out", str(tmp_path / "zip"), *args]) == 0
    assert main(["evaluate", str(exported), "--preset", "discrete", "--out", str(tmp_path / "onnx"), *args]) == 0
    a, b = (json.loads((tmp_path / name / "summary.json").read_text()) for name in ("zip", "onnx"))
    for key in ("mean_return", "attack_success_rate", "queries_per_step", "mean_length"):
        assert a[key] == pytest.approx(b[key], rel=1e-6), key


def test_a_file_without_the_contract_is_refused(tmp_path: Path, capsys) -> None:
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"not onnx")
    assert main(["evaluate", str(bad), "--episodes", "1"]) == 2
    assert "not a readable ONNX model" in capsys.readouterr().err


@pytest.mark.parametrize("algo,env_id", [("PPO", "Pendulum-v1"), ("SAC", "Pendulum-v1"), ("PPO", "CartPole-v1")])
def test_other_algorithms_export_with_their_output_heads(tmp_path: Path, algo: str, env_id: str) -> None:
    """Clipping (PPO), the tanh + rescaling to [-2, 2] (SAC) and logits travel into the ONNX file."""
    import gymnasium as gym
    import stable_baselines3

    options = {"n_steps": 32, "batch_size": 32} if algo == "PPO" else {"learning_starts": 10, "buffer_size": 100}
    model = getattr(stable_baselines3, algo)("MlpPolicy", gym.make(env_id), seed=0, device="cpu", **options)
    model.save(tmp_path / "m")
    assert main(["export", str(tmp_path / "m.zip"), "--out", str(tmp_path / "m.onnx")]) == 0
    from zodrive.policies.safe_load import load_policy_network
    from zodrive.policies.victims import network_victim

    network = load_policy_network(tmp_path / "m.zip")
    reference = network_victim(network.net, network.kind, network.obs_shape)
    x = np.random.default_rng(0).uniform(-3, 3, (64, *network.obs_shape)).astype(np.float32)
    np.testing.assert_allclose(onnx_victim(tmp_path / "m.onnx").query(x), reference.query(x), rtol=1e-5, atol=1e-5)
