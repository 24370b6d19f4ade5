"""Choose a zoo run's checkpoint on tuning seeds (never the evaluation seeds) and ship it.

Each checkpoint (every 2,000 steps, and the final model) drives `--episodes` episodes from the
tuning seeds (50,000 on; evaluation starts at 100,000); the one with the highest mean return
becomes the run's `model.zip`, the last one is kept as `final.zip`, and `selection.json` lists
every candidate's numbers. Rerunning it changes nothing once `selection.json` exists.

Run: python zoo/choose_checkpoint.py models/zoo/highway-fast-dqn/seed-0 --scenario highway-fast
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import sys
from pathlib import Path

import zodrive
from zodrive.cli.common import trust_flag
from zodrive.seeds import TUNING_SEED

EPISODES = 30  # tuning episodes per candidate unless --episodes says otherwise (zoo/card.py reads it)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="a run folder written by zoo/train.py")
    parser.add_argument("--scenario", required=True, help="the zodrive preset it was trained for")
    parser.add_argument("--episodes", type=int, default=EPISODES, help="tuning episodes per candidate (default: %(default)s)")
    parser.add_argument("--from-step", type=int, default=0,
                        help="only checkpoints from this step on (and the final model)")
    trust_flag(parser)  # for a network of its own, such as zoo/ego_attention.py
    args = parser.parse_args()
    if (args.run / "selection.json").exists():
        print(f"{args.run} was selected before: {json.loads((args.run / 'selection.json').read_text())['chosen']}")
        return
    checkpoints = sorted((int(re.search(r"_(\d+)_steps", p.name)[1]), p)
                         for p in args.run.glob("checkpoints/step_*_steps.zip"))
    if not checkpoints:  # the repository keeps a chosen run's model.zip and selection.json, not its checkpoints
        sys.exit(f"{args.run}/checkpoints holds no checkpoint to choose from: train the run again with "
                 f"`python zoo/train.py --scenario {args.scenario} --seed N --out {args.run}` (the seed in its "
                 "train.json), which writes them every 2,000 steps; checkpoints once committed are in git's history "
                 "(`git log --all -- 'models/zoo/*/checkpoints/*'`)")
    final = args.run / "final.zip"
    if not final.exists():
        shutil.move(args.run / "model.zip", final)
    candidates = [p for step, p in checkpoints if step >= args.from_step] + [final]
    results = []
    for path in candidates:
        r = zodrive.evaluate(str(path), args.scenario, episodes=args.episodes, seed=TUNING_SEED, envs=5,
                            trust_model=args.trust_model)
        results.append({"candidate": str(path.relative_to(args.run)), "mean_return": r.summary["mean_return"],
                        "collision_rate": r.summary["collision_rate"]})
        print(f"{path.name}: {r.summary['mean_return']:.2f} ({100 * r.summary['collision_rate']:.0f}% collisions)")
    best = max(results, key=lambda r: r["mean_return"])
    shutil.copy(args.run / best["candidate"], args.run / "model.zip")
    (args.run / "selection.json").write_text(json.dumps(
        {"script": "zoo/choose_checkpoint.py", "scenario": args.scenario, "tuning_seeds": [TUNING_SEED, TUNING_SEED + args.episodes - 1],
         **({"from_step": args.from_step} if args.from_step else {}),
         "chosen": best["candidate"], "candidates": results}, indent=2) + "\n")
    print(f"chose {best['candidate']}")


if __name__ == "__main__":
    main()
