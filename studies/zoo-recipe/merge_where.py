"""Where does the brake lose on merge, and what does brake-escape's escape win or cost there?

Drives `baseline:slower` and `baseline:brake-escape` on tuning seeds 50030-50129 and sorts the
episodes by whether the brake crashed and whether brake-escape changed lanes; prints the mean paired
difference per group, the episodes with an escape, and the per-episode best of the two.

Run: python studies/zoo-recipe/merge_where.py
"""

from __future__ import annotations

import numpy as np

import zodrive

SEED, EPISODES = 50_030, 100


def main() -> None:
    brake, escape = (zodrive.evaluate(p, "merge", episodes=EPISODES, seed=SEED).episodes
                     for p in ("baseline:slower", "baseline:brake-escape"))
    groups: dict[str, list[float]] = {}
    print("| Seed | Brake: return, steps, crashed | Brake-escape: return, steps, lane changes, right-lane share |\n|---|---|---|")
    for b, e in zip(brake, escape):
        key = f"brake {'crashed' if b['crashed'] else 'safe'}, {'escaped' if e['lane_changes'] else 'no escape'}"
        groups.setdefault(key, []).append(e["return"] - b["return"])
        if e["lane_changes"]:
            print(f"| {b['seed']} | {b['return']:.2f}, {b['length']}, {bool(b['crashed'])} | "
                  f"{e['return']:.2f}, {e['length']}, {e['lane_changes']}, {e['right_lane_share']:.2f} |")
    for key, diffs in sorted(groups.items()):
        print(f"{key}: {len(diffs)} episodes, brake-escape minus brake {np.mean(diffs):+.2f} on average")
    means = [np.mean([x["return"] for x in r]) for r in (brake, escape)]
    best = np.mean([max(b["return"], e["return"]) for b, e in zip(brake, escape)])
    print(f"brake {means[0]:.2f}, brake-escape {means[1]:.2f}, the better of the two per episode {best:.2f}")


if __name__ == "__main__":
    main()
