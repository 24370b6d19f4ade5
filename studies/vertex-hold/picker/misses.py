"""When does vertex hold miss the target? From an evaluation's per-step log (`steps.jsonl`, written by
`zodrive evaluate`, not committed: rerun the cell to get it): the share of steps on which the victim did not
take the target, split into misses right after a step that hit (a held vertex that stopped working, or an
episode's first step) and misses after a miss (a fresh vertex that did not work), and the actions taken on
the missed steps. Usage: python studies/vertex-hold/picker/misses.py CELL [CELL ...]"""
import collections
import json
import sys
from pathlib import Path

for cell in sys.argv[1:]:
    episodes = collections.defaultdict(list)
    for line in (Path(cell) / "steps.jsonl").read_text().splitlines():
        row = json.loads(line)
        episodes[row["episode"]].append((row["step"], row["success"], row["action"]))
    steps = after_hit = after_miss = 0
    actions: collections.Counter = collections.Counter()
    for rows in episodes.values():
        hit = True
        for _, success, action in sorted(rows):
            steps += 1
            if not success:
                after_hit, after_miss = after_hit + hit, after_miss + (not hit)
                actions[action] += 1
            hit = success
    print(f"{cell}: {steps} steps, missed on {(after_hit + after_miss) / steps:.1%}: after a hit "
          f"{after_hit / steps:.1%}, after a miss {after_miss / steps:.1%}; actions on the missed steps "
          f"{dict(sorted(actions.items()))}")
