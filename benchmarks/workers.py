"""`--workers 1` against `--workers 2` for one bench row, side by side in one run.

Times `zodrive bench MODEL --scenario S --episodes N --workers W` for each W, alternating (W = 1, 2, 1, 2,
...), each into a fresh board, and checks that every run gave the same row (a worker count changes the
time, never a number). Measure on a quiet machine: a second job on a 2-core machine takes the core the
second worker needs (issue 63 saw --workers 2 slower than 1 on a shared machine: 5 min 12 s against
2 min 45 s).

    . .venv/bin/activate && python benchmarks/workers.py --episodes 10 --repeats 1

Ends with one line: workers_1_s=<median> workers_2_s=<median> speedup=<1 over 2> same_rows=<True|False>

What committed runs printed: log workers.txt in results/benchmarks.txt (docs/bench.md says which run each is;
`zodrive pack --logs --unpack results/benchmarks` gives them back as results/benchmarks/NAME.txt). To keep a new
run's:

    python benchmarks/workers.py [options] > results/benchmarks/NAME.txt
    zodrive pack --logs results/benchmarks   # folds it in (a log of the same name is replaced)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import time
from pathlib import Path

from alternate import alternate  # benchmarks/alternate.py, beside this script

ROOT = Path(__file__).resolve().parents[1]


def one(model: str, scenario: str, episodes: int, workers: int, board: Path) -> tuple[float, dict]:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    start = time.perf_counter()
    subprocess.run(["zodrive", "bench", model, "--scenario", scenario, "--episodes", str(episodes), "--workers",
                    str(workers), "--board", str(board), "--name", "row", "--no-progress"], check=True, env=env,
                   capture_output=True, text=True)
    took = time.perf_counter() - start
    row = json.loads((board / scenario / "row" / "row.json").read_text())
    return took, {k: row[k] for k in ("clean", "attacked", "brake")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default=str(ROOT / "models" / "ppo-highway-fast"))
    parser.add_argument("--scenario", default="highway-fast")
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--repeats", type=int, default=1)
    args = parser.parse_args()
    med, same = alternate((1, 2), lambda workers, board: one(args.model, args.scenario, args.episodes, workers, board),
                          args.repeats, "workers")
    print(f"workers_1_s={med[1]:.1f} workers_2_s={med[2]:.1f} speedup={med[1] / med[2]:.2f} same_rows={same}")


if __name__ == "__main__":
    main()
