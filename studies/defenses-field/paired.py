"""A defended system's 300 clean episodes beside the undefended policy's and the brake's, on the same seeds.

Reads `runs/DEFENSE-clean300` (made by `zodrive evaluate models/zoo/highway-fast-dqn/seed-0 --preset
highway-fast --defense DEFENSE --episodes 300 --seed 100000 --out ...`) and the committed bench cells of
the undefended DQN and of the brake (`results/bench/highway-fast/dqn-seed-0`, protocol highway-fast-v4).

    python studies/defenses-field/paired.py temporal@3 smooth@0.02
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from zodrive.evaluation import store
from zodrive.evaluation.stats import paired_difference_ci

HERE = Path(__file__).parent
ROW = Path("results/bench/highway-fast/dqn-seed-0")


def episodes(cell: Path) -> dict[int, dict]:
    """Seed -> episode record of an evaluation, in its folder or packed (zodrive.evaluation.store)."""
    return {r["seed"]: r for r in store.episodes(cell)}


def describe(name: str, eps: dict[int, dict]) -> str:
    ret = np.array([r["return"] for r in eps.values()])
    return (f"{name:14s} {len(eps)} episodes: return {ret.mean():.2f}, collisions {100 * np.mean([r['crashed'] for r in eps.values()]):.0f} %, "
            f"speed {np.mean([r['mean_speed'] for r in eps.values()]):.1f} m/s, lane changes/episode "
            f"{np.mean([r['lane_changes'] for r in eps.values()]):.2f}")


def main() -> None:
    plain = episodes(store.names(ROW / "clean" / "cells", "*-none")[0])
    brake = episodes(store.names(ROW.parent / "brake" / "cells", "*-none")[0])
    print(describe("undefended", plain))
    print(describe("brake", brake))
    for defense in sys.argv[1:]:
        mine = episodes(HERE / "runs" / f"{defense}-clean300")
        seeds = sorted(mine)
        assert seeds == sorted(plain) == sorted(brake), "not the same seeds"
        print(describe(defense, mine))
        for other, theirs in (("undefended", plain), ("brake", brake)):
            mean, low, high = paired_difference_ci([mine[s]["return"] for s in seeds], [theirs[s]["return"] for s in seeds])
            print(f"  {defense} minus {other}: {mean:+.2f} ({low:+.2f} to {high:+.2f}), paired 95 % CI")


if __name__ == "__main__":
    main()
