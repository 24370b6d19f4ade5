"""Tuning-seed table of zoo runs beside the constant baselines on the same tuning seeds.

Reads each run's `selection.json` (written by zoo/choose_checkpoint.py: every checkpoint's mean return
over tuning seeds 50000-50029) and evaluates the constant actions on those seeds, so that a recipe is
judged before any evaluation seed is seen.

Run: python studies/zoo-recipe/tuning_table.py models/zoo/roundabout-dqn/seed-0 /tmp/zoo-g95/roundabout/seed-0 ...
"""

from __future__ import annotations

import json
import sys
from functools import cache
from pathlib import Path

import zodrive
from zodrive.seeds import TUNING_SEED


@cache
def constant(name: str, scenario: str, episodes: int) -> tuple[float, float]:
    r = zodrive.evaluate(f"baseline:{name}", scenario, episodes=episodes, seed=TUNING_SEED)
    return r.summary["mean_return"], r.summary["collision_rate"]


def main() -> None:
    print("| Run | gamma | Chosen | Tuning return | Collisions | Best constant (return, collisions) |")
    print("|---|---|---|---|---|---|")
    for run in map(Path, sys.argv[1:]):
        sel = json.loads((run / "selection.json").read_text())
        train = json.loads((run / "train.json").read_text())
        best = next(c for c in sel["candidates"] if c["candidate"] == sel["chosen"])
        episodes = sel["tuning_seeds"][1] - sel["tuning_seeds"][0] + 1
        consts = {n: constant(n, sel["scenario"], episodes) for n in ("slower", "idle", "faster")}
        top = max(consts, key=lambda n: consts[n][0])
        print(f"| {run} | {train.get('gamma', 0.8)} | {sel['chosen']} | {best['mean_return']:.2f} | "
              f"{100 * best['collision_rate']:.0f}% | {top} {consts[top][0]:.2f} ({100 * consts[top][1]:.0f}%) |")


if __name__ == "__main__":
    main()
