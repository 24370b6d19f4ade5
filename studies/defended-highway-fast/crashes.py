"""Crash by crash at eps 0.05: the brake, and two learned drivers behind the shield (issue 64's goal).

    python studies/defended-highway-fast/crashes.py

Reads the committed cells: the brake's clean cell (`results/bench/highway-fast/brake`), the official
row `dqn-seed-0+shield@0.05` (the shield version its key names: v5 until 2026-12-07, v6 since), and
the four cells of `imitation-seed-0+shield@0.05` run here under shield v5
(`imitation-shield.jsonl.gz`, the bench stopped after its random-search cells: see the README).
For each cell of the 100 attacked episodes (seeds 100000-100099): return, collisions, the crashed
seeds beyond the brake's, speed and lane changes per episode.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from zodrive.evaluation import store

HERE = Path(__file__).parent
BENCH = Path("results/bench/highway-fast")
FIRST = 100  # the protocol's attacked episodes: the first 100 seeds


def show(label: str, folder: Path, brake: set[int]) -> set[int]:
    episodes = [e for e in store.episodes(folder) if e["seed"] < 100000 + FIRST]
    crashed = {e["seed"] for e in episodes if e["crashed"]}
    summary = store.summary(folder)
    ret = np.mean([e["return"] for e in episodes])
    which = f"beyond the brake's: {sorted(crashed - brake) or '-'}" if brake else f"crashed: {sorted(crashed)}"
    speed = np.mean([e["mean_speed"] for e in episodes])
    print(f"{label:58s} {len(episodes):3d} ep.  return {ret:.2f}  collisions {len(crashed):2d}  {which}  "
          f"speed {speed:.1f}  lane changes/ep {np.mean([e['lane_changes'] for e in episodes]):.2f}"
          + (f"  queries/step {summary['queries_per_step']:.0f}" if summary.get("queries_per_step") else ""))
    return crashed


def main() -> None:
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
