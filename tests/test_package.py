"""The package stands on its own: configs and the demo model are package data."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from zodrive.config import config_root, demo_model, models_dir
from zodrive.envs import load_preset

REPO = Path(__file__).resolve().parents[1]


def test_a_folder_named_like_a_config_does_not_shadow_it(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "discrete").mkdir()  # e.g. left by `--out discrete`
    (tmp_path / "configs" / "presets").mkdir(parents=True)  # an unrelated configs/ folder
    (tmp_path / "configs" / "presets" / "discrete.yaml").write_text("highway: {}\n")
    assert load_preset("discrete")["highway"]["action"]["type"] == "DiscreteMetaAction"
    assert config_root() == Path(__import__("zodrive").__file__).parent / "configs"


def test_models_folder_follows_the_flag(tmp_path: Path, monkeypatch, capsys) -> None:
    from zodrive.cli import main

    monkeypatch.delenv("ZODRIVE_MODELS", raising=False)
    assert models_dir() == Path("models")
    assert main(["--models", str(tmp_path / "nope"), "baselines"]) == 2
    assert "not a folder" in capsys.readouterr().err
    assert demo_model().is_file()


@pytest.mark.slow
def test_a_built_wheel_runs_without_the_checkout(tmp_path: Path) -> None:
    """`pip wheel .`, install it alone into a folder, run from an empty directory."""
    wheels, site, work = tmp_path / "wheels", tmp_path / "site", tmp_path / "work"
    work.mkdir()
    subprocess.run([sys.executable, "-m", "pip", "wheel", str(REPO), "--no-deps", "-q", "-w", str(wheels)], check=True)
    wheel = next(wheels.glob("zodrive-*.whl"))
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target", str(site), str(wheel)],
                   check=True)
    env = {**os.environ, "PYTHONPATH": str(site)}
    env.pop("ZODRIVE_CONFIGS", None)

    def run(*args: str) -> str:
        proc = subprocess.run([sys.executable, "-m", "zodrive", *args], cwd=work, env=env, capture_output=True,
                              text=True, timeout=900)
        assert proc.returncode == 0, proc.stderr
        return proc.stdout

    where = subprocess.run([sys.executable, "-c", "import zodrive; print(zodrive.__file__)"], cwd=work, env=env,
                           capture_output=True, text=True, check=True).stdout
    assert where.startswith(str(site))
    assert "discrete" in run("env", "list") and "continuous" in run("env", "list")
    assert "DiscreteMetaAction" in run("env", "show", "discrete")
    out = run("demo", "--episodes", "1", "--out", str(work / "demo"))
    assert "cut the mean return" in out


def test_a_missing_model_is_reported_before_torch_is_imported(tmp_path: Path) -> None:
    code = ("import sys; from zodrive.cli import main; "
            f"rc = main(['compare', 'baseline:slower', {str(tmp_path / 'nope.zip')!r}, '--out', {str(tmp_path / 'c')!r}]); "
            "print(rc, 'torch' in sys.modules, 'highway_env' in sys.modules)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert proc.stdout.split() == ["2", "False", "False"]
    assert "model file not found" in proc.stderr


@pytest.mark.slow
def test_a_fresh_clone_resumes_the_committed_reproduction(tmp_path: Path) -> None:
    """`git clone`, then the README's reproduce command: every cell is on disk, none recomputed."""
    clone = tmp_path / "clone"
    subprocess.run(["git", "clone", "-q", str(REPO), str(clone)], check=True)
    env = {**os.environ, "PYTHONPATH": str(clone / "src")}
    env.pop("ZODRIVE_MODELS", None)
    proc = subprocess.run([sys.executable, "-m", "zodrive", "reproduce", "--out", "results/reproduction"], cwd=clone,
                          env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    computed = [line for line in proc.stderr.splitlines() if line.startswith("cell ")]
    assert computed == []
    assert "| DQN | Initial Training |" in proc.stdout
