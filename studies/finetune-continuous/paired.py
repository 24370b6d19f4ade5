"""Per-episode comparison of two evaluations on the same seeds (issue 22, item 2).

Usage: python studies/finetune-continuous/paired.py BASE_EVAL_DIR OTHER_EVAL_DIR [...]
Prints, for each OTHER against BASE: the mean per-episode return difference, the crashed seeds of
each, and on the episodes neither crashed the mean difference and how many went up / down.
"""
import sys

import numpy as np

from zodrive.evaluation import store


def load(folder: str) -> dict[int, dict]:
    return {row["seed"]: row for row in store.episodes(folder)}  # its folder, or its line in a pack


base = load(sys.argv[1])
for folder in sys.argv[2:]:
    other = load(folder)
    seeds = sorted(set(base) & set(other))
    diff = np.array([other[s]["return"] - base[s]["return"] for s in seeds])
    calm = [s for s in seeds if not base[s]["crashed"] and not other[s]["crashed"]]
    calm_diff = np.array([other[s]["return"] - base[s]["return"] for s in calm])
    print(f"{folder} vs {sys.argv[1]}: {len(seeds)} seeds, mean difference {diff.mean():+.2f}; crashed: base "
          f"{[s for s in seeds if base[s]['crashed']]}, other {[s for s in seeds if other[s]['crashed']]}; "
          f"neither crashed: {len(calm)} episodes, mean difference {calm_diff.mean():+.2f}, "
          f"up in {(calm_diff > 0).sum()}, down in {(calm_diff < 0).sum()}")
