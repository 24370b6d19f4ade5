"""Collisions of two cells compared seed by seed: each cell's rate with its 95 % CI
(`zodrive.evaluation.stats.rate_ci`), the seeds only one of them crashes on, and the exact McNemar
test on those discordant seeds (two-sided binomial test, p = 0.5: under "the same collision rate"
either cell is as likely to be the one that crashes). Both cells start every episode from the same
traffic, so the pairs are what differs. Usage: python studies/shield/paired_crashes.py CELL_A CELL_B"""
import sys
from pathlib import Path

from scipy.stats import binomtest

from zodrive.evaluation import store
from zodrive.evaluation.stats import paired_difference_ci, rate_ci


def episodes(cell: Path) -> dict[int, dict]:
    return {row["seed"]: row for row in store.episodes(cell)}  # its folder, or its line in a pack


a_cell, b_cell = map(Path, sys.argv[1:3])
a, b = episodes(a_cell), episodes(b_cell)
seeds = sorted(set(a) & set(b))
for name, cell in ((a_cell.name, a), (b_cell.name, b)):
    crashed = [s for s in seeds if cell[s]["crashed"]]
    low, high = rate_ci(len(crashed), len(seeds))
    print(f"{name}: {len(crashed)}/{len(seeds)} crashed ({100 * len(crashed) / len(seeds):.1f} %, 95 % CI "
          f"{100 * low:.1f}-{100 * high:.1f} %), seeds {crashed}")
only_a = [s for s in seeds if a[s]["crashed"] and not b[s]["crashed"]]
only_b = [s for s in seeds if b[s]["crashed"] and not a[s]["crashed"]]
p = binomtest(len(only_a), len(only_a) + len(only_b)).pvalue if only_a or only_b else 1.0
print(f"only {a_cell.name}: {only_a}; only {b_cell.name}: {only_b}; exact McNemar p = {p:.3f}")
diff, low, high = paired_difference_ci([a[s]["return"] for s in seeds], [b[s]["return"] for s in seeds])
print(f"return {a_cell.name} - {b_cell.name}: {diff:+.2f} [{low:+.2f}, {high:+.2f}] over {len(seeds)} seeds")
