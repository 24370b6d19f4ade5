"""Input that would run silently, ignored or meaningless, is refused in one line; SIGTERM ends a run
as Ctrl-C does."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from zodrive.cli import main



@pytest.mark.parametrize("args, says", [
    (["evaluate", "baseline:slower", "--defense", "kinematic"], "changes nothing"),
    (["evaluate", "baseline:slower", "--attack", ""], "names no attack"),
    (["compare", "baseline:slower", "--attacks", "random-search", "--eps", "0.05", "--address", "1.2.3.4:1"],
     "needs --backend ray"),
])
def test_a_meaningless_option_is_refused(args: list[str], says: str, tmp_path: Path, capsys) -> None:
    out = ["--out", str(tmp_path / "out")] if args[0] == "compare" else []
    assert main([*args, *out, "--episodes", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert says in err and err.count("\n") == 1


@pytest.mark.parametrize("defense", ["shield", "temporal", "smooth@0.02"])
def test_a_defense_before_a_constant_action_is_refused_before_any_folder(defense: str, tmp_path: Path,
                                                                          capsys) -> None:
    """Side by side (two episodes, so lockstep) as one at a time: refused where the job is made."""
    out = tmp_path / "out"
    assert main(["evaluate", "baseline:slower", "--preset", "highway-fast", "--defense", defense, "--episodes", "2",
                 "--out", str(out), "--no-progress"]) == 2
    assert "changes nothing" in capsys.readouterr().err and not out.exists()


def test_sigterm_keeps_what_was_written(tmp_path: Path) -> None:
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "zodrive", "evaluate", "baseline:slower", "--preset", "highway-fast",
                             "--episodes", "500", "--envs", "1", "--out", str(out), "--no-progress"],
                            stderr=subprocess.PIPE, text=True, env={**os.environ, "OMP_NUM_THREADS": "1"})
    deadline = time.time() + 120
    while time.time() < deadline and not (out / "episodes.jsonl").is_file():
        time.sleep(0.5)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and "interrupted; results written so far are kept" in err
