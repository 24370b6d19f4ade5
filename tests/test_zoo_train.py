"""zoo/train.py on zodrive's copy of a scenario trains the very same network as on highway-env's, and a
recipe flag such as `--n-steps` reaches SB3 and the run's record."""

from __future__ import annotations

import io
import json
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
import torch

ROOT = Path(__file__).resolve().parents[1]


def _weights(run: Path) -> dict[str, torch.Tensor]:
    with zipfile.ZipFile(run / "model.zip") as z:
        return torch.load(io.BytesIO(z.read("policy.pth")), map_location="cpu", weights_only=True)


@pytest.mark.slow
def test_the_fast_env_trains_the_same_weights(tmp_path: Path) -> None:
    runs = {}
    for flag in ([], ["--fast-env"]):
        out = tmp_path / ("fast" if flag else "stock")
        subprocess.run([sys.executable, str(ROOT / "zoo" / "train.py"), "--scenario", "intersection", "--net", "attention",
                        "--gamma", "0.95", "--steps", "300", "--every", "300", "--seed", "0", "--n-steps", "3",
                        "--out", str(out), *flag], check=True, capture_output=True, text=True)
        train = json.loads((out / "train.json").read_text())
        assert train["fast_env"] is bool(flag) and train["n_steps"] == 3
        with zipfile.ZipFile(out / "model.zip") as z:  # SB3's own record of the run's settings
            assert json.loads(z.read("data"))["n_steps"] == 3
        runs[bool(flag)] = _weights(out)
    stock, fast = runs[False], runs[True]
    assert stock.keys() == fast.keys() and all(torch.equal(stock[k], fast[k]) for k in stock)
