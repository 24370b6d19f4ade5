"""The README's Python code blocks run as written (a newcomer copies them)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"


def python_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.S)


def test_every_python_block_parses_and_imports_what_it_uses() -> None:
    blocks = python_blocks()
    assert len(blocks) >= 2
    for block in blocks:
        compile(block, "README.md", "exec")
        assert "import " in block, f"a README block without imports fails as written:\n{block[:200]}"


@pytest.mark.slow
def test_the_python_api_block_runs(tmp_path: Path) -> None:
    block = next(b for b in python_blocks() if "zodrive.evaluate" in b)
    script = tmp_path / "api.py"
    script.write_text(block)
    (tmp_path / "models").symlink_to(README.parent / "models")  # the block reads the shipped PPO, as from a checkout
    run = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True,
                         timeout=1200, env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.count("Result(") == 2 and (tmp_path / "attacked.png").stat().st_size > 0
