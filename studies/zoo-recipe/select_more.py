"""Choose a zoo run's checkpoint on 100 tuning episodes (seeds 50200-50299) instead of the 30 that
zoo/choose_checkpoint.py uses, and write the choice as RUN_OUT/model.zip (with the run's train.json),
so that validate.py can score it on seeds 50030-50129, which neither choice saw.

Run: python studies/zoo-recipe/select_more.py models/zoo/highway-fast-dqn/seed-1 /work/zoo-exp/select100/seed-1 --scenario highway-fast
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import sys
from pathlib import Path

import zodrive
from zodrive.seeds import TUNING_SEED

FIRST = TUNING_SEED + 200


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--scenario", required=True)
    parser.add_argument("--episodes", type=int, default=100)
    args = parser.parse_args()
    candidates = sorted(args.run.glob("checkpoints/step_*_steps.zip"),
                        key=lambda p: int(re.search(r"_(\d+)_steps", p.name)[1])) + [args.run / "final.zip"]
    if len(candidates) == 1:  # the repository keeps no run's checkpoints: zoo/train.py writes them
        sys.exit(f"{args.run}/checkpoints holds no checkpoint: train the run with zoo/train.py (its train.json says how)")
    results = []
    for path in candidates:
        r = zodrive.evaluate(str(path), args.scenario, episodes=args.episodes, seed=FIRST, envs=5)
        results.append((r.summary["mean_return"], path))
        print(f"{path.name}: {r.summary['mean_return']:.2f} ({100 * r.summary['collision_rate']:.0f}% collisions)", flush=True)
    best = max(results)[1]
    args.out.mkdir(parents=True, exist_ok=True)
    shutil.copy(best, args.out / "model.zip")
    shutil.copy(args.run / "train.json", args.out / "train.json")
    (args.out / "chosen.json").write_text(json.dumps({"chosen": best.name, "seeds": [FIRST, FIRST + args.episodes - 1]}) + "\n")
    print(f"chose {best.name}")


if __name__ == "__main__":
    main()
