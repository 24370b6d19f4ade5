"""Transfer from a surrogate (`--attack transfer:DIR`, `zodrive surrogate-train`): PGD on an MLP the attacker
fitted from the victim's watched decisions, fed with zero victim queries per step. The harness judges each
step afterwards (the oracle's `referee`, counted apart); the surrogate is plain arrays, read without pickle."""

from __future__ import annotations

import json
import os
import pickle
from pathlib import Path

import numpy as np
import pytest
import torch

from toys import context, linear_victim, logging_victim, observations
from zodrive.attacks import AttackSpec
from zodrive.attacks.oracle import QueryOracle
from zodrive.attacks.spec import load_attack
from zodrive.attacks.transfer import FORMAT, META_FILE, WEIGHTS_FILE, load_surrogate, network, save_weights
from zodrive.attacks.victim import Victim
from zodrive.errors import ZodriveError
from zodrive.system import attack_observations

EPS = 0.3


def surrogate_folder(folder: Path, seed: int = 0, width: int = 16) -> Path:
    """A surrogate folder as surrogate-train writes one, with a random MLP over (5, 5) observations."""
    torch.manual_seed(seed)
    net = network(25, [width, width], 5)
    folder.mkdir(parents=True, exist_ok=True)
    save_weights(net, folder / WEIGHTS_FILE)
    meta = {"format": FORMAT, "victim": "toy", "victim_sha256": "0" * 64, "preset": {"name": "toy"},
            "obs_shape": [5, 5], "n_actions": 5, "widths": [width, width]}
    (folder / META_FILE).write_text(json.dumps(meta))
    return folder


def build(folder: Path, victim: Victim, **options):
    return AttackSpec(attack="transfer", adversary=str(folder), eps=EPS, steps=20, **options).build(
        victim, **context())


def test_an_attacked_step_sends_the_victim_nothing_and_the_referee_judges_after(tmp_path: Path, monkeypatch) -> None:
    log: list[np.ndarray] = []
    attack, objective, oracle = build(surrogate_folder(tmp_path / "s"), logging_victim(linear_victim(seed=2), log))
    seen_during: list[int] = []
    perturb = type(attack).perturb

    def spy(self, x0, oracle, objective, *, trace=False):  # what the victim had received when the attack returned
        result = perturb(self, x0, oracle, objective, trace=trace)
        seen_during.append(len(log))
        return result

    monkeypatch.setattr(type(attack), "perturb", spy)
    monkeypatch.setattr(QueryOracle, "gradient", lambda *a, **k: pytest.fail("transfer asked for a gradient"))
    x0 = observations(4, seed=3)
    for _ in range(3):  # three steps
        result, _ = attack_observations(x0, attack, objective, oracle)
        assert result.queries.tolist() == [0, 0, 0, 0] and oracle.step_queries == 0
    assert seen_during == [0, 8, 16]  # nothing reached the victim while the attack ran
    assert oracle.total_queries == 0 and oracle.referee_queries == 3 * 2 * 4 == sum(len(b) for b in log)
    assert result.referee_queries is not None and result.referee_queries.tolist() == [2, 2, 2, 2]
    # the referee asked about the clean and the fed observations, one row per call, as the policy acts
    assert all(len(b) == 1 for b in log)
    sent = np.concatenate(log[-8:])
    np.testing.assert_array_equal(sent[:4], x0)
    np.testing.assert_array_equal(sent[4:], result.x_adv)
    victim_out = linear_victim(seed=2).query(result.x_adv)
    clean_out = linear_victim(seed=2).query(x0)
    assert result.success.tolist() == ((victim_out.argmax(1) == 3) & (clean_out.argmax(1) != 3)).tolist()
    assert result.already.tolist() == (clean_out.argmax(1) == 3).tolist()


@pytest.mark.parametrize("vehicles", [None, 1])
def test_every_fed_point_is_inside_the_threat_model(tmp_path: Path, vehicles: int | None) -> None:
    x0 = observations(6, seed=7)
    x0[:, 1:, 1] = 0.999  # clean values at the edge of the box
    attack, objective, oracle = build(surrogate_folder(tmp_path / "s", seed=1), linear_victim(seed=2),
                                      vehicles=vehicles, step_size=0.1)
    result, _ = attack_observations(x0, attack, objective, oracle)
    delta = result.x_adv - x0
    assert np.abs(delta).max() <= EPS + 1e-6 and np.abs(delta).max() > 0  # it moved, inside the ball
    assert np.all(result.x_adv >= -1.0) and np.all(result.x_adv <= 1.0)  # the box
    np.testing.assert_array_equal(result.x_adv[:, :, 0], x0[:, :, 0])  # presence frozen
    moved = np.any(delta != 0, axis=-1).sum(axis=-1)
    assert np.all(moved <= (5 if vehicles is None else vehicles))


def test_the_surrogate_round_trips_without_pickle(tmp_path: Path, monkeypatch) -> None:
    folder = surrogate_folder(tmp_path / "s", seed=4)
    torch.manual_seed(4)
    original = network(25, [16, 16], 5).eval()

    def refuse(*args, **kwargs):
        raise AssertionError("something was unpickled")

    monkeypatch.setattr(pickle, "loads", refuse)
    monkeypatch.setattr(pickle, "load", refuse)
    monkeypatch.setattr(pickle, "Unpickler", refuse)
    monkeypatch.setattr(torch, "load", refuse)
    net, meta = load_surrogate(folder)
    x = torch.from_numpy(observations(5).reshape(5, -1))
    with torch.no_grad():
        assert torch.equal(net(x), original(x))
    assert meta["widths"] == [16, 16]


class _Payload:
    def __init__(self, marker: str) -> None:
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def test_weights_that_would_need_pickle_are_refused_without_running_them(tmp_path: Path) -> None:
    marker = tmp_path / "pwned"
    folder = surrogate_folder(tmp_path / "s")
    with open(folder / WEIGHTS_FILE, "wb") as handle:  # an .npz holding an object array: loading it unpickles
        np.savez(handle, weight_0=np.array([_Payload(str(marker))], dtype=object))
    with pytest.raises(ZodriveError, match="is not a surrogate's weights"):
        load_surrogate(folder)
    (folder / WEIGHTS_FILE).write_bytes(pickle.dumps(_Payload(str(marker))))
    with pytest.raises(ZodriveError, match="is not a surrogate's weights"):
        load_surrogate(folder)
    assert not marker.exists()
    np.savez(folder / "other.npz", weight_0=np.zeros((3, 3), dtype=np.float32))
    (folder / "other.npz").replace(folder / WEIGHTS_FILE)
    with pytest.raises(ZodriveError, match="does not fit the network"):
        load_surrogate(folder)


@pytest.mark.parametrize("name, message", [
    ("transfer:{missing}", "surrogate folder not found"),
    ("transfer:{empty}", "is not a surrogate (no surrogate.json"),
    ("transfer:", "names no folder"),
    ("transfer", "needs a surrogate: --attack transfer:DIR"),
])
def test_a_bad_folder_is_one_line_and_exit_2(tmp_path: Path, capsys, name: str, message: str) -> None:
    from zodrive.cli import main

    (tmp_path / "empty").mkdir()
    attack = name.format(missing=tmp_path / "missing", empty=tmp_path / "empty")
    assert main(["evaluate", "baseline:rules", "--preset", "highway-fast", "--attack", attack, "--eps", "0.05",
                 "--episodes", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


@pytest.mark.parametrize("options, refused", [
    ({"access": "decision"}, "transfer crafts on its surrogate and makes no victim query"),
    ({"n_directions": 5}, "n_directions has no effect"),
    ({"max_change": 0.01}, "max_change has no effect"),
])
def test_options_transfer_cannot_use_are_refused(tmp_path: Path, options: dict, refused: str) -> None:
    with pytest.raises(ZodriveError, match=refused):
        build(surrogate_folder(tmp_path / "s"), linear_victim(), **options)


def test_the_evaluation_key_changes_with_the_surrogates_content(tmp_path: Path) -> None:
    """A refitted surrogate is another attack: an evaluation's key holds the SHA-256 of its weights and
    description, so a resumed run never mixes two surrogates' episodes."""
    from zodrive.evaluation.evaluate import EvalJob

    def key(folder: Path) -> dict:
        spec = load_attack(f"transfer:{folder}", [f"eps={EPS}"])
        return EvalJob(model="baseline:rules", preset={"name": "toy"}, attack=spec.to_dict()).key()

    a = surrogate_folder(tmp_path / "a", seed=0)
    same = surrogate_folder(tmp_path / "same", seed=0)
    key_a = key(a)
    assert key_a["adversary"].startswith("sha256:")
    assert {**key(same), "attack": None} == {**key_a, "attack": None}  # the same content: the same attack
    surrogate_folder(a, seed=1)  # refitted in place: the same path, other weights
    assert key(a)["adversary"] != key_a["adversary"] and key(a)["attack"] == key_a["attack"]


def test_a_surrogate_fitted_to_another_model_is_refused(tmp_path: Path) -> None:
    from zodrive.attacks.transfer import check_surrogate

    folder = surrogate_folder(tmp_path / "s")
    model = tmp_path / "model.zip"
    model.write_bytes(b"another model")
    with pytest.raises(ZodriveError, match="was fitted against"):
        check_surrogate(folder, model_file=str(model), preset={"name": "toy"}, defense=None)


@pytest.mark.integration
def test_surrogate_train_then_transfer_on_the_real_preset(tmp_path: Path, capsys) -> None:
    """A tiny fit on the real preset (5-step episodes) from watched decisions only, then an evaluation that
    makes 0 victim queries per step; the harness's rows are counted apart."""
    from zodrive.cli import main

    root = Path(__file__).resolve().parents[1]
    model, out = str(root / "models" / "dqn-close"), tmp_path / "surrogate"
    short = ["--env-set", "max_episode_steps=5"]
    assert main(["surrogate-train", model, "--out", str(out), "--episodes", "3", "--held-out", "1", "--epochs", "2",
                 "--width", "8", *short]) == 0
    assert "watched 15 decisions" in capsys.readouterr().out
    train = json.loads((out / "train.json").read_text())
    assert train["victim_queries"] == 0 and train["seeds"] == [50000, 50002] and train["held_out_decisions"] == 5
    assert main(["evaluate", model, "--attack", f"transfer:{out}", "--eps", "0.05", "--episodes", "2",
                 "--out", str(tmp_path / "eval"), "--no-progress", *short]) == 0
    summary = json.loads((tmp_path / "eval" / "summary.json").read_text())
    assert summary["queries_per_step"] == 0.0 and summary["victim_rows"]["attack_queries"] == 0
    assert summary["victim_rows"]["referee"] == 2 * summary["victim_rows"]["decisions"] == 20
    assert summary["attack_success_rate"] is not None
