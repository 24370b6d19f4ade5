"""What the bench's 100 episodes can show: the margin a policy needs so that its paired CI clears a constant.

For every zoo row of the committed board, the clean return minus each constant action's, episode by
episode on the protocol's seeds. The spread of those differences fixes how wide the paired 95% CI is,
and so how large a true margin must be before a CI shows it (normal approximation):
- clears with probability 1/2 at a true margin of 1.96 sd/sqrt(n), with 80 % at 2.80 sd/sqrt(n);
- a policy whose true margin is m clears with probability Phi(m sqrt(n) / sd - 1.96);
- episodes for 80 % at m: (2.80 sd / m)^2.
Nothing is run: it reads `results/bench/` (the rows `zodrive bench` wrote).

Run: python studies/zoo-recipe/power.py [--board results/bench] [--margin M ...]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from zodrive.evaluation import store

CONSTANTS = ("baseline-slower", "baseline-idle", "baseline-faster")
Z95, Z80 = 1.959964, 0.841621


def clean_returns(folder: Path) -> dict[int, float]:
    (cell,) = store.names(folder / "cells", "*-none")  # its folder, or its line in cells.jsonl.gz
    return {r["seed"]: r["return"] for r in store.episodes(cell, needs=("seed", "return"))}


def probability(margin: float, sd: float, n: int) -> float:
    """P(the paired CI's low end > 0) for a true margin, normal approximation."""
    return 0.5 * math.erfc(-(margin * math.sqrt(n) / sd - Z95) / math.sqrt(2))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--board", type=Path, default=Path("results/bench"))
    parser.add_argument("--margin", type=float, nargs="*", default=[0.5, 0.8, 1.0, 1.3],
                        help="true margins to give the chance of clearing for")
    args = parser.parse_args()
    head = " | ".join(f"P(clear) at +{m:g}" for m in args.margin)
    print(f"| Scenario | Policy | Δ closest constant | sd of Δ | CI half-width | margin for 80 % | {head} |")
    print("|---|---|---|---|---|---|" + "---|" * len(args.margin))
    for scenario in sorted(p for p in args.board.iterdir() if p.is_dir()):
        constants = {c: clean_returns(scenario / c) for c in CONSTANTS if (scenario / c).is_dir()}
        for folder in sorted(p for p in scenario.iterdir() if p.is_dir() and not p.name.startswith("baseline-")):
            mine = clean_returns(folder)
            worst = None
            for name, theirs in constants.items():
                seeds = sorted(mine)
                if sorted(theirs) != seeds:
                    raise SystemExit(f"{folder} and {name} are not on the same seeds")
                diff = np.array([mine[s] - theirs[s] for s in seeds])
                n, mean, sd = len(diff), float(diff.mean()), float(diff.std(ddof=1))
                low = mean - Z95 * sd / math.sqrt(n)
                if worst is None or low < worst[0]:
                    worst = (low, name, mean, sd, n)
            if worst is None:
                continue
            low, name, mean, sd, n = worst
            chances = " | ".join(f"{probability(m, sd, n):.2f}" for m in args.margin)
            print(f"| {scenario.name} | {folder.name} | {mean:+.2f} vs {name.removeprefix('baseline-')} "
                  f"(low {low:+.2f}) | {sd:.2f} | ±{Z95 * sd / math.sqrt(n):.2f} | "
                  f"+{(Z95 + Z80) * sd / math.sqrt(n):.2f} | {chances} |")


if __name__ == "__main__":
    main()
