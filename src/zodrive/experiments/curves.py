"""`zodrive curves`: learning curves of training runs, side by side (table and plot).

Reads each run's `monitor.monitor.csv` (SB3's Monitor: one row per training episode) and
bins the episodes by the training step at which they ended, so runs of different lengths
and settings compare on one axis: mean training return and episode length per bin.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import numpy as np

from zodrive.config import read_text
from zodrive.errors import ZodriveError
from zodrive.evaluation.report import headless_pyplot, save_figure


def read_monitor(run: Path) -> tuple[np.ndarray, np.ndarray]:
    """(episode returns, episode lengths) of a run folder, in training order."""
    path = run / "monitor.monitor.csv"
    if not path.is_file():
        raise ZodriveError(f"{path} not found (is {run} a training run folder?)")
    return read_monitor_csv(path)


def read_monitor_csv(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """SB3's Monitor file (a JSON header line, then `r,l,t` rows): (returns, lengths). A file
    that is not UTF-8, lacks the columns or holds a row that is not numbers is one line naming it."""
    lines = read_text(path, "monitor file", max_bytes=None).splitlines()
    rows = list(csv.DictReader(lines[1:]))  # the first line is SB3's JSON header
    if rows and not {"r", "l"} <= set(rows[0]):
        raise ZodriveError(f"monitor file {path} has no 'r' and 'l' columns (not SB3's Monitor file?)")
    returns, lengths = [], []
    for number, row in enumerate(rows, start=3):
        try:
            returns.append(float(row["r"]))
            lengths.append(int(row["l"]))
        except (TypeError, ValueError):
            raise ZodriveError(f"monitor file {path} is damaged: line {number} is not a row of numbers") from None
    return np.array(returns, dtype=float), np.array(lengths, dtype=int)


def binned(run: Path, bin_steps: int) -> list[dict[str, Any]]:
    """Mean return and length of the episodes that ended in each `bin_steps` window."""
    returns, lengths = read_monitor(run)
    ends = np.cumsum(lengths)
    rows = []
    for start in range(0, int(ends[-1]) if len(ends) else 0, bin_steps):
        mask = (ends > start) & (ends <= start + bin_steps)
        if mask.any():
            rows.append({"step": start + bin_steps, "mean_return": float(returns[mask].mean()),
                         "mean_length": float(lengths[mask].mean()), "episodes": int(mask.sum())})
    return rows


def labels(runs: list[Path]) -> list[str]:
    """The shortest path tails that tell the runs apart."""
    for depth in range(1, 1 + max(len(run.parts) for run in runs)):
        names = ["/".join(run.parts[-depth:]) for run in runs]
        if len(set(names)) == len(names):
            return names
    return [str(run) for run in runs]


def curves_markdown(runs: list[Path], bin_steps: int) -> str:
    """One row per run: mean training return (and length) per step window."""
    data = {run: {r["step"]: r for r in binned(run, bin_steps)} for run in runs}
    steps = sorted({s for rows in data.values() for s in rows})
    lines = ["| Run | " + " | ".join(f"≤{_kilo(s)}" for s in steps) + " |",
             "|---|" + "---|" * len(steps)]
    for label, rows in zip(labels(runs), data.values()):
        cells = [f"{rows[s]['mean_return']:.0f} / {rows[s]['mean_length']:.0f}" if s in rows else "" for s in steps]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot_curves(runs: list[Path], bin_steps: int, path: Path) -> None:
    plt = headless_pyplot()
    fig, ax = plt.subplots(figsize=(7, 3.8))
    for run, label in zip(runs, labels(runs)):
        rows = binned(run, bin_steps)
        ax.plot([r["step"] for r in rows], [r["mean_return"] for r in rows], ".-", label=label)
    ax.set_xlabel("training step")
    ax.set_ylabel(f"mean training return per {_kilo(bin_steps)} steps")
    ax.legend(fontsize=7)
    save_figure(fig, path)


def _kilo(steps: int) -> str:
    """25000 -> '25k', 500 -> '0.5k'."""
    return f"{steps / 1000:g}k"
