"""Nothing is unpickled unless the user says so: a run folder from someone else resumes no code."""

from __future__ import annotations

import os
import pickle
import shutil
from pathlib import Path

import pytest

from zodrive.errors import ZodriveError
from zodrive.training.recipes import load_recipe, train


class _Payload:
    def __reduce__(self):
        return (os.mkdir, (os.environ["ZODRIVE_MARKER"],))


def _run(out: Path) -> None:
    recipe = load_recipe("dqn", ["hyperparameters.learning_starts=50", "checkpoint_every=100"])
    recipe["total_timesteps"] = 100
    train(recipe, out, progress_bar=False)


def test_a_strangers_run_folder_resumes_nothing(tmp_path: Path, monkeypatch) -> None:
    mine = tmp_path / "mine"
    _run(mine)
    assert (mine / "checkpoints" / "SIGNATURES.json").is_file()
    stranger = tmp_path / "stranger"
    shutil.copytree(mine, stranger)
    (stranger / "model.zip").unlink()
    marker = tmp_path / "ran"
    monkeypatch.setenv("ZODRIVE_MARKER", str(marker))
    buffer = stranger / "checkpoints" / "dqn_replay_buffer_100_steps.pkl"
    buffer.write_bytes(pickle.dumps(_Payload()))  # a crafted replay buffer, its signature now wrong
    recipe = load_recipe("dqn", ["hyperparameters.learning_starts=50", "checkpoint_every=100"])
    recipe["total_timesteps"] = 200
    with pytest.raises(ZodriveError, match="not written by zodrive on this machine.*--trust-model"):
        train(recipe, stranger, resume=True, progress_bar=False)
    (stranger / "checkpoints" / "SIGNATURES.json").write_text("{}")  # no signatures at all: refused the same
    with pytest.raises(ZodriveError, match="--trust-model"):
        train(recipe, stranger, resume=True, progress_bar=False)
    assert not marker.exists()
    train(recipe, mine, resume=True, progress_bar=False)  # this machine's own run resumes as before
    assert (mine / "checkpoints" / "dqn_200_steps.zip").is_file()
