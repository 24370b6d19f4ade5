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
from zodrive.evaluation.exact import attack_gap, exact, grid_bracket, min_eps
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
    summary, _ = exact_summary(net, "discrete", x0, 0.3, mask, (-1.0, 1.0), 1e-4,
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


def test_a_miss_is_an_attackable_state_the_attack_did_not_win() -> None:
    """attack_gap on a toy: won and attackable is found, attackable and not won is missed, a win the
    exact check left unknown is counted apart, a win where it says robust is a reported contradiction;
    the counts add up both ways."""
    verdict = np.array(["attackable", "attackable", "attackable", "robust", "unknown", "robust"], dtype=object)
    won = np.array([True, False, False, False, True, False])
    gap = attack_gap(verdict, won)
    assert (gap["attackable"], gap["found"], gap["missed"], gap["success"]) == (3, 1, 2, 2)
    assert gap["miss_rate"] == pytest.approx(2 / 3) and gap["success_share"] == pytest.approx(2 / 6)
    assert (gap["won_robust"], gap["won_unknown"]) == (0, 1)
    assert gap["found"] + gap["missed"] == gap["attackable"]
    assert gap["found"] + gap["won_robust"] + gap["won_unknown"] == gap["success"]
    everything = attack_gap(verdict, verdict == "attackable")
    assert everything["missed"] == 0 and everything["miss_rate"] == 0.0
    bad = attack_gap(verdict, np.array([False, False, False, True, False, False]))
    assert bad["won_robust"] == 1 and bad["miss_rate"] == 1.0  # reported, not dropped
    assert attack_gap(np.array(["robust"], dtype=object), np.array([False]))["miss_rate"] is None


def _ramp() -> nn.Sequential:
    """2 inputs, 2 actions: score(0) = 0.3, score(1) = x[0]; from x[0] = c the action changes exactly
    beyond radius 0.3 - c (a tie keeps action 0)."""
    net = nn.Sequential(nn.Linear(2, 2), nn.ReLU(), nn.Linear(2, 2)).eval()
    with torch.no_grad():
        net[0].weight.copy_(torch.tensor([[1.0, 0.0], [-1.0, 0.0]]))
        net[0].bias.zero_()
        net[2].weight.copy_(torch.tensor([[0.0, 0.0], [1.0, -1.0]]))
        net[2].bias.copy_(torch.tensor([0.3, 0.0]))
    return net


def test_the_bisection_brackets_the_known_smallest_radius() -> None:
    net = _ramp()
    c = np.array([0.0, 0.1, -0.15, -0.5], dtype=np.float32)  # smallest radius 0.3, 0.2, 0.45, 0.8
    x0 = np.stack([c, np.zeros_like(c)], axis=1)
    mask, grid = np.ones(2, dtype=np.float32), [0.1, 0.6]
    verdicts = [exact(net, "discrete", x0, eps, mask, -1.0, 1.0).verdict for eps in grid]
    assert list(verdicts[0]) == ["robust"] * 4 and list(verdicts[1]) == ["attackable"] * 3 + ["robust"]
    found = min_eps(net, "discrete", x0, grid, verdicts, mask, (-1.0, 1.0), 10.0, steps=8)
    truth = 0.3 - c.astype(np.float64)
    assert found.broken == 0 and not found.stopped.any() and found.checks == 3 * 8
    assert (found.lower[:3] < truth[:3]).all() and (truth[:3] <= found.upper[:3] + 1e-6).all()
    assert (found.upper[:3] - found.lower[:3] <= 0.5 / 256 + 1e-12).all()
    assert found.lower[3] == 0.6 and found.upper[3] == np.inf  # robust at every radius checked


def test_a_grid_that_breaks_nesting_is_counted() -> None:
    lower, upper, broken = grid_bracket([0.01, 0.02], [np.array(["attackable", "unknown"], dtype=object),
                                                        np.array(["robust", "attackable"], dtype=object)])
    assert broken == 1 and list(upper) == [0.01, 0.02] and list(lower) == [0.02, 0.0]


def test_certify_reports_each_attacks_misses_against_exact(tmp_path: Path, monkeypatch, capsys) -> None:
    """certify --attack ... --exact --min-eps: per attack found + missed = exactly attackable, the
    per-state strings give the same counts, the black-box ensemble misses no more than any of its
    attacks, no win where exact says robust, and the bisection's bracket is nested in the grid's."""
    import zodrive.evaluation.certify as certify_module

    x0, _ = _states(12, seed=6)
    x0[:, :, 1:] *= 0.3
    monkeypatch.setattr(certify_module, "episode_states", lambda *args: x0)
    out = tmp_path / "gap"
    assert main(["certify", str(DRIVER), "--eps", "0.005", "0.02", "--attack", "random-search", "pgd", "--exact",
                 "--min-eps", "--out", str(out)]) == 0
    assert "miss rate" in capsys.readouterr().out
    result = json.loads((out / "certify.json").read_text())
    for row in result["rows"]:
        per = row["per_state"]
        assert per["exact"].count("a") == row["exact"]["attackable"] and len(per["exact"]) == len(x0)
        for side in row["attacks"]:
            gap, won = side["vs_exact"], np.array([b == "1" for b in per[side["attack"]]])
            assert gap["found"] + gap["missed"] == gap["attackable"] == row["exact"]["attackable"]
            assert gap["found"] + gap["won_robust"] + gap["won_unknown"] == gap["success"] == won.sum()
            assert gap["success_share"] == pytest.approx(side["success_share"]) and gap["won_robust"] == 0
            assert gap["missed"] == sum(v == "a" and not w for v, w in zip(per["exact"], won))
        ensemble = row["exact"]["black_box_ensemble"]
        assert ensemble["attacks"] == ["random-search"]  # PGD is white-box: not in the ensemble
        assert ensemble["missed"] == row["attacks"][0]["vs_exact"]["missed"]
    found = result["min_eps"]
    lower, upper = (np.array([np.inf if v is None else v for v in found[k]]) for k in ("lower", "upper"))
    assert (lower < upper).all() and found["broken"] == 0
    first = [0.005 if a == "a" else 0.02 if b == "a" else np.inf
             for a, b in zip(result["rows"][0]["per_state"]["exact"], result["rows"][1]["per_state"]["exact"])]
    assert (upper <= np.array(first)).all()
    assert found["beyond_grid"] == int(np.isinf(upper).sum())
    assert main(["certify", str(DRIVER), "--eps", "0.01", "--min-eps"]) == 2
    assert capsys.readouterr().err.strip().startswith("zodrive: error:")
