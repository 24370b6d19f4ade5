"""Held-out tuning check of zoo runs: each run's chosen checkpoint against the constant brake on
tuning seeds that the checkpoint choice did not see (50030 on; the choice used 50000-50029, the
bench starts at 100000), paired episode by episode. A recipe is adopted on this table, before any
of its models is benched.

Run: python studies/zoo-recipe/validate.py highway-fast RUN [RUN ...] [--episodes 100]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import zodrive
from zodrive.evaluation.stats import paired_difference_ci
from zodrive.seeds import TUNING_SEED

FIRST = TUNING_SEED + 30  # after the 30 episodes zoo/choose_checkpoint.py selects on


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario")
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--episodes", type=int, default=100)
    args = parser.parse_args()
    brake = zodrive.evaluate("baseline:slower", args.scenario, episodes=args.episodes, seed=FIRST)
    theirs = [e["return"] for e in sorted(brake.episodes, key=lambda e: e["episode"])]
    print(f"seeds {FIRST}-{FIRST + args.episodes - 1}; brake {brake.summary['mean_return']:.2f} "
          f"({100 * brake.summary['collision_rate']:.0f}% collisions)")
    print("| Run | gamma | Return | Collisions | Δ brake (paired 95% CI) |")
    print("|---|---|---|---|---|")
    for run in args.runs:
        gamma = json.loads((run / "train.json").read_text()).get("gamma", 0.8)
        r = zodrive.evaluate(str(run / "model.zip"), args.scenario, episodes=args.episodes, seed=FIRST, envs=5)
        mean, low, high = paired_difference_ci([e["return"] for e in sorted(r.episodes, key=lambda e: e["episode"])], theirs)
        print(f"| {run} | {gamma} | {r.summary['mean_return']:.2f} | {100 * r.summary['collision_rate']:.0f}% | "
              f"{mean:+.2f} ({low:+.2f} to {high:+.2f}) |", flush=True)


if __name__ == "__main__":
    main()
