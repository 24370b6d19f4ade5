"""Exact verdicts (a MILP per state) agree with everything that can check them: CROWN's
certificates, attacks, a dense grid, the float32 network and SB3's own policy on each
counterexample; the time limit turns into counted unknowns."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest
import torch
from torch import nn

from zodrive.attacks.spec import AttackSpec
from zodrive.cli import main
from zodrive.evaluation.certify import certify, threat_box
from zodrive.evaluation.exact import exact
from zodrive.policies.victims import network_victim

ROOT = Path(__file__).resolve().parents[1]
DRIVER = ROOT / "models" / "dqn-driver"
CONTEXT = {"features": ("presence", "x", "y", "vx", "vy"), "bounds": (-1.0, 1.0), "n_actions": 5}


def _net(widths: tuple[int, ...], seed: int = 0) -> nn.Sequential:
    torch.manual_seed(seed)
    layers: list[nn.Module] = []
    for a, b in itertools.pairwise(widths):
        layers += [nn.Linear(a, b), nn.ReLU()]
    return nn.Sequential(*layers[:-1]).eval()


def _states(n: int, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Kinematics-like states (n, 5, 5) with the presence column at 1, and the default mask (presence frozen)."""
    x = np.random.default_rng(seed).uniform(-1, 1, (n, 5, 5)).astype(np.float32)
    x[:, :, 0] = 1.0
    mask = np.ones((5, 5), dtype=np.float32)
    mask[:, 0] = 0.0
    return x, mask


def _check_counterexamples(net: nn.Module, x0: np.ndarray, eps: float, mask: np.ndarray, result) -> int:
    """Every counterexample lies in the threat box and changes the float32 network's action; returns how many."""
    flat = x0.reshape(len(x0), -1)
    lo, hi = threat_box(flat, eps, mask.reshape(-1), -1.0, 1.0)
    rows = np.flatnonzero(result.verdict == "attackable")
    assert np.isnan(result.counterexample[result.verdict != "attackable"]).all()
    points = result.counterexample[rows]
    assert points.dtype == np.float32 and not np.isnan(points).any()
    assert (points >= lo[rows]).all() and (points <= hi[rows]).all()
    assert (points[:, mask.reshape(-1) == 0] == flat[rows][:, mask.reshape(-1) == 0]).all()  # frozen stays put
    with torch.no_grad():
        clean = net(torch.from_numpy(flat[rows])).argmax(1)
        moved = net(torch.from_numpy(points)).argmax(1)
    assert (clean != moved).all()
    return len(rows)


def test_every_crown_certified_state_is_proved_robust_by_the_milp_alone() -> None:
    """crown_first=False: the MILP itself must prove the states CROWN certifies (it may prove more)."""
    net, (x0, mask) = _net((25, 32, 32, 5)), _states(60)
    eps = 0.01
    cert = certify(net, "discrete", x0, eps, mask, -1.0, 1.0)
    result = exact(net, "discrete", x0, eps, mask, -1.0, 1.0, time_limit=30, crown_first=False, falsify=False)
    assert 0 < cert.certified.sum() < len(x0)  # neither side vacuous at this radius
    assert (result.verdict[cert.certified] == "robust").all()
    assert (result.crown == cert.certified).all()
    assert (result.verdict != "unknown").all()
    assert (result.verdict == "attackable").any()
    _check_counterexamples(net, x0, eps, mask, result)


@pytest.mark.parametrize("eps", [0.02, 0.05])
def test_every_state_an_attack_wins_is_attackable_and_never_robust(eps: float) -> None:
    net, (x0, mask) = _net((25, 32, 32, 5)), _states(60, seed=5)
    victim = network_victim(net, "discrete", (5, 5))
    won = np.zeros(len(x0), dtype=bool)
    for attack, options in (("random-search", {"steps": 200, "n_directions": 20}), ("pgd", {"steps": 100})):
        atk, objective, oracle = AttackSpec(attack=attack, eps=eps, target="none", **options).build(victim, **CONTEXT)
        oracle.begin_episode()
        won |= atk.perturb(x0, oracle, objective).success
    assert 0 < won.sum() < len(x0)
    for falsify in (False, True):  # the MILP alone, and with the gradient search before it
        result = exact(net, "discrete", x0, eps, mask, -1.0, 1.0, time_limit=30, falsify=falsify)
        assert (result.verdict[won] == "attackable").all()
        assert (result.verdict != "unknown").all()
        assert _check_counterexamples(net, x0, eps, mask, result) >= won.sum()


def _grid_changes(net: nn.Module, x0: np.ndarray, lo: np.ndarray, hi: np.ndarray, n: int = 401) -> bool:
    a, b = np.meshgrid(np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n))
    grid = np.stack([a.ravel(), b.ravel()], axis=1).astype(np.float32)
    grid = np.clip(grid, lo.astype(np.float32), hi.astype(np.float32))
    with torch.no_grad():
        return bool((net(torch.from_numpy(grid)).argmax(1) != net(torch.from_numpy(x0[None])).argmax(1)).any())


@pytest.mark.parametrize("seed", [0, 1, 3])
def test_a_two_input_net_agrees_with_a_dense_grid(seed: int) -> None:
    """On 2 inputs a 401 x 401 grid over each box decides too: the verdicts match state for state,
    and robustness shrinks as the box grows."""
    net = _net((2, 16, 16, 3), seed=seed)
    with torch.no_grad():
        net[0].weight *= 8  # a bumpier net: several decision boundaries cross [-1, 1]^2
    x0 = np.random.default_rng(seed).uniform(-0.9, 0.9, (40, 2)).astype(np.float32)
    mask = np.ones(2, dtype=np.float32)
    robust_before = np.ones(len(x0), dtype=bool)
    for eps in (0.02, 0.05, 0.1):
        result = exact(net, "discrete", x0, eps, mask, -1.0, 1.0, time_limit=30, falsify=False)
        lo, hi = threat_box(x0.astype(np.float64), eps, mask, -1.0, 1.0)
        grid = np.array([_grid_changes(net, x0[i], lo[i], hi[i]) for i in range(len(x0))])
        assert (result.verdict != "unknown").all()
        assert ((result.verdict == "attackable") == grid).all(), (eps, result.verdict, grid)
        robust = result.verdict == "robust"
        assert not (robust & ~robust_before).any()  # robust in a bigger box: robust in the smaller one
        robust_before = robust
    assert 0 < robust_before.sum() < len(x0)


def test_shipped_driver_counterexamples_replay_in_sb3() -> None:
    """The shipped DQN driver: each MILP counterexample changes the action of the rebuilt float32
    network and of stable-baselines3's own loaded policy."""
    from stable_baselines3 import DQN

    from zodrive.policies.safe_load import load_policy_network

    network = load_policy_network(DRIVER / "model.zip")
    x0, mask = _states(6, seed=3)
    x0[:, :, 1:] *= 0.3  # nearer the traffic this driver has seen
    result = exact(network.net, network.kind, x0, 0.02, mask, -1.0, 1.0, time_limit=60, falsify=False)
    assert _check_counterexamples(network.net, x0, 0.02, mask, result) > 0
    model = DQN.load(DRIVER / "model.zip", device="cpu")
    rows = np.flatnonzero(result.verdict == "attackable")
    moved, _ = model.predict(result.counterexample[rows].reshape(-1, 5, 5), deterministic=True)
    clean, _ = model.predict(x0[rows], deterministic=True)
    assert (moved != clean).all()


def test_qr_dqn_quantile_means_are_decided_and_replay(tmp_path: Path) -> None:
    """QR-DQN acts on the mean over quantiles (folded into the last layer here): its counterexamples
    change sb3-contrib's own action, and the MILP proves at least what CROWN proves."""
    import gymnasium as gym

    from zodrive.policies.safe_load import load_policy_network

    sb3_contrib = pytest.importorskip("sb3_contrib")
    sb3_contrib.QRDQN("MlpPolicy", gym.make("CartPole-v1"), seed=0, device="cpu", learning_starts=10,
                      buffer_size=100).save(tmp_path / "qr")
    network = load_policy_network(tmp_path / "qr.zip")
    x0 = np.random.default_rng(0).uniform(-1, 1, (40, 4)).astype(np.float32)
    mask = np.ones(4, dtype=np.float32)
    cert = certify(network.net, network.kind, x0, 0.1, mask, float("-inf"), float("inf"))
    result = exact(network.net, network.kind, x0, 0.1, mask, float("-inf"), float("inf"), time_limit=30,
                   crown_first=False, falsify=False)
    assert (result.verdict[cert.certified] == "robust").all() and (result.verdict != "unknown").all()
    rows = np.flatnonzero(result.verdict == "attackable")
    assert len(rows) > 0
    model = sb3_contrib.QRDQN.load(tmp_path / "qr.zip", device="cpu")
    moved, _ = model.predict(result.counterexample[rows], deterministic=True)
    clean, _ = model.predict(x0[rows], deterministic=True)
    assert (moved != clean).all()


def test_the_time_limit_makes_counted_unknowns() -> None:
    """A state HiGHS cannot settle within the limit (it starts, and stops on time) and states given
    no time at all are unknown and counted as timed out, never guessed."""
    from zodrive.evaluation.exact import exact_summary

    net, (x0, mask) = _net((25, 128, 128, 5), seed=2), _states(6, seed=2)
    hard = exact(net, "discrete", x0[:1], 0.3, mask, -1.0, 1.0, time_limit=2.0, falsify=False)
    assert hard.verdict[0] == "unknown" and hard.timed_out[0] and 1.5 < hard.seconds[0] < 6
    summary = exact_summary(net, "discrete", x0, 0.3, mask, (-1.0, 1.0), 1e-4,
                            np.zeros(len(x0), dtype=bool), None)
    # the gradient search runs before the limit applies: what it finds is confirmed, the rest is unknown
    assert summary["unknown"] == summary["timed_out"] >= 1 and summary["robust"] == 0
    assert summary["unknown"] + summary["attackable"] == len(x0) and summary["seconds_max"] < 5
    decided = exact(net, "discrete", x0[1:], 0.3, mask, -1.0, 1.0, time_limit=30)
    assert not decided.timed_out.any() and (decided.verdict == "attackable").all()


def test_certify_exact_on_the_command_line(tmp_path: Path, monkeypatch, capsys) -> None:
    """certify --exact: counts in the table and in certify.json that add up; refusals in one line."""
    import zodrive.evaluation.certify as certify_module

    x0, _ = _states(12, seed=6)
    x0[:, :, 1:] *= 0.3
    monkeypatch.setattr(certify_module, "episode_states", lambda *args: x0)  # no highway-env episodes
    out = tmp_path / "ce"
    assert main(["certify", str(DRIVER), "--eps", "0.005", "0.02", "--exact", "--time-limit", "20",
                 "--out", str(out)]) == 0
    assert "exact (MILP, 20 s/state)" in capsys.readouterr().out
    rows = json.loads((out / "certify.json").read_text())["rows"]
    for row in rows:
        ex = row["exact"]
        assert ex["robust"] + ex["attackable"] + ex["unknown"] == row["states"] == len(x0)
        assert ex["crown_certified"] == round(row["certified_share"] * len(x0)) <= ex["robust"]
        assert ex["contradictions"] == 0 and ex["time_limit"] == 20
    assert rows[1]["exact"]["robust"] <= rows[0]["exact"]["robust"]
    for argv in (["certify", str(ROOT / "models" / "ppo-highway-fast"), "--eps", "0.01", "--exact"],  # Tanh
                 ["certify", str(ROOT / "models" / "ddpg-driver"), "--eps", "0.01", "--exact"],       # continuous
                 ["certify", str(DRIVER), "--eps", "0.01", "--time-limit", "5"],                      # no --exact
                 ["certify", str(DRIVER), "--eps", "0.01", "--exact", "--time-limit", "0"]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) <= 2 and err[-1].startswith("zodrive: error:") and "Traceback" not in "".join(err)
