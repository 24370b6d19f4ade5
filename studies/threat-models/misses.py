"""What an attack fed on the steps it missed: counts of (won / missed) x (L-inf 0 / above 0) from steps.jsonl.

    python studies/threat-models/misses.py dqn-driver-score-0.05 dqn-driver-decision-0.05 ...

Reads studies/threat-models/runs/CELL/steps.jsonl (written by run.py; not committed).
"""

import collections
import json
import sys
from pathlib import Path

RUNS = Path(__file__).resolve().parent / "runs"

for cell in sys.argv[1:]:
    counts: collections.Counter = collections.Counter()
    with open(RUNS / cell / "steps.jsonl") as f:
        for line in f:
            s = json.loads(line)
            if not s.get("attacked", True):
                continue
            counts[("won" if s["success"] else "missed", "fed L-inf > 0" if s["linf"] > 0 else "fed clean")] += 1
    print(cell + ": " + ", ".join(f"{k[0]} and {k[1]}: {v}" for k, v in sorted(counts.items())))
