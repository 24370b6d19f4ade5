"""Certificates are sound: no attack ever changes a certified decision, and they are not vacuous."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from torch import nn

from zodrive.attacks.spec import AttackSpec
from zodrive.policies.victims import network_victim
from zodrive.evaluation.certify import certify, threat_box
from zodrive.cli import main

FEATURES = ("presence", "x", "y", "vx", "vy")
CONTEXT = {"features": FEATURES, "bounds": (-1.0, 1.0), "n_actions": 5}


def _net(seed: int = 0) -> nn.Sequential:
    torch.manual_seed(seed)
    return nn.Sequential(nn.Linear(25, 32), nn.ReLU(), nn.Linear(32, 32), nn.ReLU(), nn.Linear(32, 5)).eval()


def _states(n: int = 200) -> np.ndarray:
    x = np.random.default_rng(1).uniform(-1, 1, (n, 5, 5)).astype(np.float32)
    x[:, :, 0] = 1.0
    return x


@pytest.mark.parametrize("eps", [0.003, 0.01])  # this random network's margins are small: 67 % / 26 % certified
def test_no_attack_flips_a_certified_state(eps: float) -> None:
    net, x0 = _net(), _states()
    mask = np.ones((5, 5), dtype=np.float32)
    mask[:, 0] = 0.0  # presence frozen, as the default threat model
    cert = certify(net, "discrete", x0, eps, mask, -1.0, 1.0)
    assert 0 < cert.certified.mean() < 1  # neither vacuous nor trivially everything at these radii
    victim = network_victim(net, "discrete", (5, 5))
    for attack, options in (("random-search", {"steps": 200, "n_directions": 20}), ("pgd", {"steps": 200})):
        spec = AttackSpec(attack=attack, eps=eps, target="none", **options)
        atk, objective, oracle = spec.build(victim, **CONTEXT)
        oracle.begin_episode()
        result = atk.perturb(x0, oracle, objective)
        assert not (result.success & cert.certified).any()  # from below and from above never overlap
    # the corners of the box of a certified state keep its action (a direct check of the bound)
    rng = np.random.default_rng(2)
    flat = x0.reshape(len(x0), -1)
    lo, hi = threat_box(flat, eps, mask.reshape(-1), -1.0, 1.0)
    for i in np.flatnonzero(cert.certified)[:20]:
        corners = np.where(rng.random((256, 25)) < 0.5, lo[i], hi[i]).astype(np.float32)
        with torch.no_grad():
            assert (net(torch.from_numpy(corners)).argmax(1) == net(torch.from_numpy(flat[i:i + 1])).argmax(1)).all()


def test_the_certified_share_falls_as_eps_grows() -> None:
    net, x0 = _net(), _states()
    mask = np.ones((5, 5), dtype=np.float32)
    shares = [certify(net, "discrete", x0, eps, mask, -1.0, 1.0).certified.mean() for eps in (0.0001, 0.01, 0.1)]
    assert shares[0] >= shares[1] >= shares[2] and shares[0] > 0.9 and shares[2] < 0.5


def test_a_continuous_bound_holds_for_every_corner() -> None:
    torch.manual_seed(3)
    net = nn.Sequential(nn.Linear(25, 16), nn.Tanh(), nn.Linear(16, 2), nn.Tanh()).eval()
    x0 = _states(50)
    mask = np.ones((5, 5), dtype=np.float32)
    cert = certify(net, "continuous", x0, 0.05, mask, -1.0, 1.0)
    flat = x0.reshape(len(x0), -1)
    lo, hi = threat_box(flat, 0.05, mask.reshape(-1), -1.0, 1.0)
    rng = np.random.default_rng(0)
    with torch.no_grad():
        clean = net(torch.from_numpy(flat))
        for i in range(len(x0)):
            corners = np.where(rng.random((128, 25)) < 0.5, lo[i], hi[i]).astype(np.float32)
            moved = (net(torch.from_numpy(corners)) - clean[i]).abs().max().item()
            assert moved <= cert.bound[i] + 1e-6


def test_certify_reads_a_shipped_model(tmp_path: Path, capsys) -> None:
    root = Path(__file__).resolve().parents[1]
    out = tmp_path / "cert"
    assert main(["certify", str(root / "models" / "dqn"), "--eps", "0.001", "0.01", "--episodes", "1",
                 "--env-set", "max_episode_steps=20", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "certified" in printed and (out / "certify.json").is_file()
    assert main(["certify", "baseline:slower", "--eps", "0.01"]) == 2  # no network to bound


@pytest.mark.parametrize("algo,env_id", [("QRDQN", "CartPole-v1"), ("PPO", "CartPole-v1"), ("SAC", "Pendulum-v1"),
                                         ("PPO", "Pendulum-v1")])
def test_bounds_hold_through_every_output_head(tmp_path: Path, algo: str, env_id: str) -> None:
    """Quantile means, tanh + rescaling to [-2, 2], the Gaussian mean's clip: corners never beat the bound."""
    import gymnasium as gym
    import stable_baselines3

    from zodrive.policies.safe_load import load_policy_network

    sb3_contrib = pytest.importorskip("sb3_contrib")
    cls = getattr(sb3_contrib, algo, None) or getattr(stable_baselines3, algo)
    options = {"n_steps": 32, "batch_size": 32} if algo == "PPO" else {"learning_starts": 10, "buffer_size": 100}
    cls("MlpPolicy", gym.make(env_id), seed=0, device="cpu", **options).save(tmp_path / "m")
    network = load_policy_network(tmp_path / "m.zip")
    x0 = np.random.default_rng(0).uniform(-1, 1, (40, *network.obs_shape)).astype(np.float32)
    mask = np.ones(network.obs_shape, dtype=np.float32)
    eps = 0.05
    cert = certify(network.net, network.kind, x0, eps, mask, float("-inf"), float("inf"))
    lo, hi = threat_box(x0.reshape(len(x0), -1), eps, mask.reshape(-1), float("-inf"), float("inf"))
    rng = np.random.default_rng(1)
    with torch.no_grad():
        clean = network.net(torch.from_numpy(x0.reshape(len(x0), -1)))
        for i in range(len(x0)):
            corners = torch.from_numpy(np.where(rng.random((128, lo.shape[1])) < 0.5, lo[i], hi[i]).astype(np.float32))
            out = network.net(corners)
            if network.kind == "discrete" and cert.certified[i]:
                assert (out.argmax(1) == clean[i].argmax()).all()
            if network.kind == "continuous":
                assert (out - clean[i]).abs().max().item() <= cert.bound[i] + 1e-6


def test_attacks_and_certificates_sandwich_the_same_states(tmp_path: Path, capsys) -> None:
    """`certify --attack`: each attack's success beside the certified share on the same states;
    a sound certificate is never beaten (no contradictions) and success + certified <= 1."""
    import json

    root = Path(__file__).resolve().parents[1]
    out = tmp_path / "sandwich"
    assert main(["certify", str(root / "models" / "dqn-driver"), "--eps", "0.005", "0.05", "--episodes", "1",
                 "--env-set", "max_episode_steps=25", "--attack", "random-search", "pgd", "--out", str(out)]) == 0
    assert "unknown" in capsys.readouterr().out
    rows = json.loads((out / "certify.json").read_text())["rows"]
    for row in rows:
        assert [side["attack"] for side in row["attacks"]] == ["random-search", "pgd"]
        for side in [*row["attacks"], row["any_attack"]]:
            assert side.get("contradictions", 0) == 0
            assert side["success_share"] + row["certified_share"] <= 1.0 + 1e-12
            assert side["unknown_share"] == pytest.approx(1 - side["success_share"] - row["certified_share"])
    assert rows[1]["any_attack"]["success_share"] > rows[0]["any_attack"]["success_share"]  # a wider ball wins more
    assert main(["certify", str(root / "models" / "dqn-driver"), "--eps", "0.01", "--attack", "no-such"]) == 2
