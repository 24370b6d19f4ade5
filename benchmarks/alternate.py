"""Two settings of one command, timed alternately in one run (A, B, A, B, ...), each in a fresh folder, and
whether every run gave the same result: the loop of `workers.py` and `envs.py`, where a setting must change
the time and never a number."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import Any, Callable


def alternate(settings: tuple[int, ...], run: Callable[[int, Path], tuple[float, Any]], repeats: int,
              label: str) -> tuple[dict[int, float], bool]:
    """`run(setting, folder) -> (seconds, result)` for each setting in turn, `repeats` times; the median
    seconds per setting, and whether every result equals the first."""
    times: dict[int, list[float]] = {setting: [] for setting in settings}
    results = []
    for _ in range(repeats):
        for setting in settings:
            folder = Path(tempfile.mkdtemp(prefix=f"zodrive-{label}{setting}-"))
            try:
                took, result = run(setting, folder)
            finally:
                shutil.rmtree(folder, ignore_errors=True)
            times[setting].append(took)
            results.append(result)
            print(f"{label}={setting}: {took:.1f} s", flush=True)
    return {s: sorted(t)[len(t) // 2] for s, t in times.items()}, all(r == results[0] for r in results)
