"""Opening a model never runs code from it; the rebuilt network is SB3's, bit for bit."""

from __future__ import annotations

import base64
import json
import os
import pickle
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch

from zodrive.policies.loading import load_model
from zodrive.policies.resolve import load_victim
from zodrive.policies.safe_load import sha256, shipped_sums
from zodrive.policies.victims import sb3_victim
from zodrive.cli import main
from zodrive.envs import load_preset

ROOT = Path(__file__).resolve().parents[1]


class _Payload:
    """Unpickling this creates a file: the proof that a loader ran code from a model."""

    def __init__(self, marker: str) -> None:
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def _crafted(tmp_path: Path, source: Path, *, in_data: bool, in_weights: bool) -> tuple[Path, Path]:
    marker = tmp_path / "pwned"
    crafted = tmp_path / "crafted.zip"
    payload = base64.b64encode(pickle.dumps(_Payload(str(marker)))).decode()
    with zipfile.ZipFile(source) as src, zipfile.ZipFile(crafted, "w") as dst:
        for item in src.infolist():
            raw = src.read(item.filename)
            if item.filename == "data" and in_data:
                data = json.loads(raw)
                data["policy_class"][":serialized:"] = payload
                data["observation_space"][":serialized:"] = payload
                raw = json.dumps(data).encode()
            if item.filename == "policy.pth" and in_weights:
                raw = pickle.dumps(_Payload(str(marker)))
            dst.writestr(item, raw)
    return crafted, marker


@pytest.mark.parametrize("where", ["data", "weights"])
def test_a_crafted_model_runs_no_code(tmp_path: Path, where: str, capsys) -> None:
    crafted, marker = _crafted(tmp_path, ROOT / "models" / "dqn" / "model.zip",
                               in_data=where == "data", in_weights=where == "weights")
    code = main(["evaluate", str(crafted), "--preset", "discrete", "--episodes", "1", "--no-progress", "--env-set",
                 "max_episode_steps=5"])
    assert not marker.exists()
    if where == "weights":
        assert code == 2 and "corrupt or not a plain" in capsys.readouterr().err
    else:  # the pickled fields are never read: the model evaluates on its plain data alone
        assert code == 0
    # SB3's loader would unpickle: refused without --trust-model (or as corrupt, before that)
    with pytest.raises(Exception, match="--trust-model" if where == "data" else "corrupt"):
        load_model(crafted)
    assert not marker.exists()


@pytest.mark.parametrize("name", ["dqn", "ddpg", "dqn-adv", "ddpg-adv"])
def test_rebuilt_network_equals_sb3(name: str) -> None:
    path = ROOT / "models" / name
    preset = load_preset("discrete" if name.startswith("dqn") else "continuous")
    safe, full = load_victim(str(path), preset), sb3_victim(load_model(path, preset))
    obs = np.random.default_rng(1).uniform(-1, 1, (257, 5, 5)).astype(np.float32)
    np.testing.assert_array_equal(safe.query(obs), full.query(obs))
    grads = []
    for victim in (safe, full):  # white-box baselines get the same gradients
        x = torch.from_numpy(obs[:16]).requires_grad_(True)
        victim.differentiable(x).sum().backward()
        grads.append(x.grad.numpy())
    np.testing.assert_allclose(grads[0], grads[1], atol=1e-6)


def test_shipped_models_match_their_sums() -> None:
    sums = shipped_sums(ROOT / "models")
    assert {"dqn/model.zip", "ddpg/model.zip", "dqn-adv/model.zip", "ddpg-adv/model.zip"} <= set(sums)
    for name, digest in sums.items():
        assert sha256(ROOT / "models" / name) == digest, name
        assert digest in (ROOT / "models" / Path(name).parent / "CARD.md").read_text(), f"{name}: card lacks its SHA-256"


def test_full_loading_needs_trust(tmp_path: Path) -> None:
    import gymnasium as gym
    from stable_baselines3 import DQN

    other = tmp_path / "model.zip"
    DQN("MlpPolicy", gym.make("CartPole-v1"), device="cpu").save(other)  # not a shipped model
    with pytest.raises(Exception, match="--trust-model"):
        load_model(other)
    assert load_model(other, trust=True) is not None
    assert load_model(ROOT / "models" / "dqn") is not None  # shipped: its SHA-256 is in the package's list


def test_the_packages_trusted_list_is_the_shipped_one() -> None:
    from zodrive.policies.loading import TRUSTED_SUMS

    assert TRUSTED_SUMS.read_text() == (ROOT / "models" / "SHA256SUMS").read_text()


def test_a_crafted_sums_file_trusts_nothing(tmp_path: Path, monkeypatch) -> None:
    """A stranger's checkout that lists its own zip in models/SHA256SUMS gets it unpickled by nothing."""
    models = tmp_path / "models"
    (models / "evil").mkdir(parents=True)
    crafted, marker = _crafted(tmp_path, ROOT / "models" / "dqn" / "model.zip", in_data=True, in_weights=False)
    target = models / "evil" / "model.zip"
    target.write_bytes(crafted.read_bytes())
    (models / "SHA256SUMS").write_text(f"{sha256(target)}  evil/model.zip\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("ZODRIVE_MODELS", str(models))
    with pytest.raises(Exception, match="--trust-model"):
        load_model(target)
    code = main(["adv-train", str(target), "--steps", "10", "--out", str(tmp_path / "run"), "--no-progress"])
    assert code == 2 and not marker.exists()


def test_a_model_is_loaded_once_per_process_until_the_file_changes(tmp_path: Path) -> None:
    import shutil

    from zodrive.policies.loading import load_network

    copy = tmp_path / "model.zip"
    shutil.copy("models/dqn/model.zip", copy)
    first = load_network(copy)
    assert load_network(copy) is first  # validation and episodes share one load
    shutil.copy("models/dqn-driver/model.zip", copy)  # a swapped file is read again
    assert load_network(copy) is not first


@pytest.mark.parametrize(("where", "message"), [
    ("shape", "records no readable observation shape"),
    ("n", "the action space's n is 'five', not a number of actions"),
    ("tensors", "policy.pth holds str where the tensor"),
])
def test_a_crafted_zip_with_text_for_numbers_is_one_line(tmp_path: Path, where: str, message: str, capsys) -> None:
    import io

    import torch

    crafted = tmp_path / "crafted.zip"
    with zipfile.ZipFile(ROOT / "models" / "dqn" / "model.zip") as src, zipfile.ZipFile(crafted, "w") as dst:
        for item in src.infolist():
            raw = src.read(item.filename)
            if item.filename == "data" and where in ("shape", "n"):
                data = json.loads(raw)
                if where == "shape":
                    data["observation_space"]["_shape"] = ["five", 5]
                else:
                    data["action_space"]["n"] = "five"
                raw = json.dumps(data).encode()
            if item.filename == "policy.pth" and where == "tensors":
                buffer = io.BytesIO()
                torch.save({k: "tensor" for k in torch.load(io.BytesIO(raw), weights_only=True)}, buffer)
                raw = buffer.getvalue()
            dst.writestr(item, raw)
    assert main(["evaluate", str(crafted), "--preset", "discrete", "--episodes", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
