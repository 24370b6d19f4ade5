"""Crash by crash at eps 0.05: the brake, and two learned drivers behind the shield (issue 64's goal).

    python studies/defended-highway-fast/crashes.py            # the bench's seeds
    python studies/defended-highway-fast/crashes.py unseen     # unseen.sh's seeds (section 5)

Reads the committed cells: the brake's clean cell (`results/bench/highway-fast/brake`), the official
row `dqn-seed-0+shield@0.05` (the shield version its key names: v5 until 2026-12-07, v6 since), and
the four cells of `imitation-seed-0+shield@0.05` run here under shield v5
(`imitation-shield.jsonl.gz`, the bench stopped after its random-search cells: see the README).
For each cell of the 100 attacked episodes (seeds 100000-100099): return, collisions, the crashed
seeds beyond the brake's, speed and lane changes per episode.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from zodrive.evaluation import store

HERE = Path(__file__).parent
BENCH = Path("results/bench/highway-fast")
FIRST = 100  # the protocol's attacked episodes: the first 100 seeds


def show(label: str, folder: Path, brake: set[int], first: int = 100000) -> set[int]:
    episodes = [e for e in store.episodes(folder) if e["seed"] < first + FIRST]
    crashed = {e["seed"] for e in episodes if e["crashed"]}
    summary = store.summary(folder)
    ret = np.mean([e["return"] for e in episodes])
    which = f"beyond the brake's: {sorted(crashed - brake) or '-'}" if brake else f"crashed: {sorted(crashed)}"
    speed = np.mean([e["mean_speed"] for e in episodes])
    print(f"{label:58s} {len(episodes):3d} ep.  return {ret:.2f}  collisions {len(crashed):2d}  {which}  "
          f"speed {speed:.1f}  lane changes/ep {np.mean([e['lane_changes'] for e in episodes]):.2f}"
          + (f"  queries/step {summary['queries_per_step']:.0f}" if summary.get("queries_per_step") else ""))
    return crashed


def unseen() -> None:
    """`unseen.sh`'s cells: seeds 200000-200099, which no run had seen before shield v6 was written."""
    folder = HERE / "unseen"
    brake = show("brake (always SLOWER), clean", folder / "brake", set(), first=200000)
    for name in ("v6-none", "v6-random-search", "v6-zo-signsgd", "v5-random-search"):
        if store.names(folder, name):
            show(f"dqn-seed-0+shield@0.05 {name}", folder / name, brake, first=200000)


def main() -> None:
    if sys.argv[1:] == ["unseen"]:
        unseen()
        return
    brake = show("brake (always SLOWER), clean", BENCH / "brake/cells/baseline-slower-none", set())
    version = json.loads((BENCH / "dqn-seed-0+shield@0.05/row.json").read_text())["key"].rpartition(":")[2]
    rows = [(f"dqn-seed-0+shield@0.05 {version}", BENCH / "dqn-seed-0+shield@0.05/cells", "seed-0+shield@0.05"),
            ("imitation-seed-0+shield@0.05 v5", HERE / "imitation-shield", "seed-0+shield@0.05")]  # section 3's
    for row, parent, prefix in rows:
        for name in [p.name for p in store.names(parent)]:
            if name.endswith("-none") or "eps0.05" in name:
                show(f"{row}: {name.removeprefix(prefix + '-')}", parent / name, brake)


if __name__ == "__main__":
    main()
