"""`--envs 1` against `--envs 8` for one attacked evaluation, side by side in one run.

Times `zodrive evaluate MODEL --preset P --attack A --episodes N --workers 1 --envs E [--defense D]` for
each E, alternating (E = 1, 8, 1, 8, ...), each into a fresh folder, and checks that every run wrote the
same episode records (episodes side by side change the time, never a number). Its first use: a stateful
defense (`temporal@3`), whose episodes ran one at a time until each row got its own filter (`RowFilters`).

    . .venv/bin/activate && python benchmarks/envs.py --defense temporal@3 --episodes 16

Ends with one line: envs_1_s=<median> envs_8_s=<median> speedup=<1 over 8> same_records=<True|False>
(each time includes the process start and the policy's loading, the same for both). To keep a run's log:

    python benchmarks/envs.py [options] > results/benchmarks/NAME.txt
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


def one(args: argparse.Namespace, envs: int, out: Path) -> tuple[float, list[dict]]:
    command = ["zodrive", "evaluate", args.model, "--preset", args.preset, "--attack", args.attack, "--eps",
               str(args.eps), "--query-budget", str(args.query_budget), "--episodes", str(args.episodes),
               "--workers", "1", "--envs", str(envs), "--out", str(out), "--no-progress", "--trust-model"]
    if args.defense:
        command += ["--defense", args.defense]
    start = time.perf_counter()
    subprocess.run(command, check=True, env={**os.environ, "OMP_NUM_THREADS": "1"}, capture_output=True, text=True)
    took = time.perf_counter() - start
    records = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    return took, sorted(records, key=lambda r: r["episode"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default=str(ROOT / "models" / "zoo" / "highway-fast-dqn" / "seed-0"))
    parser.add_argument("--preset", default="highway-fast")
    parser.add_argument("--attack", default="random-search-smooth")
    parser.add_argument("--eps", type=float, default=0.05)
    parser.add_argument("--query-budget", type=int, default=500)
    parser.add_argument("--defense", default=None)
    parser.add_argument("--episodes", type=int, default=16)
    parser.add_argument("--repeats", type=int, default=1)
    args = parser.parse_args()
    med, same = alternate((1, 8), lambda envs, folder: one(args, envs, folder / "run"), args.repeats, "envs")
    print(f"envs_1_s={med[1]:.1f} envs_8_s={med[8]:.1f} speedup={med[1] / med[8]:.2f} same_records={same}")


if __name__ == "__main__":
    main()
