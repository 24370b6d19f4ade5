"""Held-out tuning check of zoo runs: each run's model against every constant action of its
scenario (`baseline:slower`, `idle`, `faster`) on tuning seeds that no checkpoint choice saw
(50030 on by default, `--seed` for another unused set; zoo/choose_checkpoint.py uses 50000-50029,
the bench starts at 100000), paired
episode by episode; the margin shown is over the constant the run beats by the least (issue 48's
bar). A recipe is adopted on this table, before any of its models is benched.

Run: python studies/zoo-recipe/validate.py SCENARIO RUN [RUN ...] [--episodes 100] [--seed 50030] [--trust-model]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import zodrive
from zodrive.cli.common import trust_flag
from zodrive.evaluation.stats import paired_difference_ci
from zodrive.seeds import TUNING_SEED

FIRST = TUNING_SEED + 30  # after the 30 episodes zoo/choose_checkpoint.py selects on
CONSTANTS = ("slower", "idle", "faster")


def returns(result: zodrive.Result) -> list[float]:
    """Per-episode returns in episode (seed) order, for pairing."""
    return [e["return"] for e in sorted(result.episodes, key=lambda e: e["episode"])]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario")
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=FIRST, help="first tuning seed (default: %(default)s)")
    trust_flag(parser)  # for a network of its own, such as zoo/ego_attention.py
    args = parser.parse_args()
    constants = {}
    print(f"seeds {args.seed}-{args.seed + args.episodes - 1}")
    for name in CONSTANTS:
        r = zodrive.evaluate(f"baseline:{name}", args.scenario, episodes=args.episodes, seed=args.seed)
        constants[name] = returns(r)
        print(f"always-{name.upper()}: {r.summary['mean_return']:.2f} ({100 * r.summary['collision_rate']:.0f}% collisions)")
    print("| Run | Return | Collisions | Δ closest constant (paired 95% CI) | Δ brake (paired 95% CI) |")
    print("|---|---|---|---|---|")
    for run in args.runs:
        r = zodrive.evaluate(str(run / "model.zip"), args.scenario, episodes=args.episodes, seed=args.seed, envs=5,
                            trust_model=args.trust_model)
        margins = {name: paired_difference_ci(returns(r), theirs) for name, theirs in constants.items()}
        closest = min(margins, key=lambda name: margins[name][0])
        mean, low, high = margins[closest]
        b_mean, b_low, b_high = margins["slower"]
        print(f"| {run} | {r.summary['mean_return']:.2f} | {100 * r.summary['collision_rate']:.0f}% | "
              f"{mean:+.2f} ({low:+.2f} to {high:+.2f}) vs {closest} | {b_mean:+.2f} ({b_low:+.2f} to {b_high:+.2f}) |",
              flush=True)


if __name__ == "__main__":
    main()
