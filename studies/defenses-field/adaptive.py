"""Does the attack that adapts to a defense beat the one that does not, on a defended bench row?

For each ε of the row, each adaptive attack's cell (docs/bench.md, "Defended rows": `ADAPTIVE`) against each
non-adaptive black-box attack's cell, paired on the same episodes: mean return and collisions of both, and
the adaptive minus the other with a bootstrap 95 % CI (below 0: the adaptive attack does more harm).

    python studies/defenses-field/adaptive.py results/bench/highway-fast/dqn-seed-0+temporal@3 [ROW ...]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from zodrive.bench.bench import ADAPTIVE
from zodrive.bench.row import read_row
from zodrive.evaluation import store
from zodrive.evaluation.stats import paired_difference_ci


def cell_of(row: Path, attack: str, eps: float) -> dict[int, dict] | None:
    """Seed -> episode record of the row's cell for `attack` at `eps` (None: the row has none)."""
    found = [c for c in store.names(row / "cells", f"*-{attack}-eps{eps:g}*")
             if Path(str(c)).name.split("-eps")[0].endswith(attack)]
    return None if not found else {r["seed"]: r for r in store.episodes(found[0])}


def describe(eps: dict[int, dict]) -> str:
    ret = np.mean([r["return"] for r in eps.values()])
    crashes = sum(bool(r["crashed"]) for r in eps.values())
    return f"{ret:6.2f}, {crashes:3d} crashes"


def main(rows: list[str]) -> None:
    for path in map(Path, rows):
        row = read_row(path / "row.json")
        defense = row["defense"].partition("@")[0] if row.get("defense") else None
        adaptive = ADAPTIVE.get(defense or "", ())
        plain = [a for a in row["black_box"] if a not in adaptive]
        print(f"{path.name} ({row['protocol']}): adaptive {', '.join(adaptive) or 'none'}; "
              f"the others {', '.join(plain)}")
        for eps in [cell["eps"] for cell in row["attacked"]]:
            for a in adaptive:
                ours = cell_of(path, a, eps)
                for b in plain:
                    theirs = cell_of(path, b, eps)
                    if ours is None or theirs is None:
                        print(f"  eps {eps:g}: {a} or {b} has no cell")
                        continue
                    seeds = sorted(set(ours) & set(theirs))
                    diff = paired_difference_ci(np.array([ours[s]["return"] for s in seeds]),
                                                np.array([theirs[s]["return"] for s in seeds]))
                    print(f"  eps {eps:g}: {a} {describe(ours)} | {b} {describe(theirs)} | {a} minus {b} "
                          f"on {len(seeds)} episodes: {diff[0]:+.2f} ({diff[1]:+.2f} to {diff[2]:+.2f})")


if __name__ == "__main__":
    main(sys.argv[1:])
