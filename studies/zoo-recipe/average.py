"""Average the weights of a zoo run's last checkpoints (stochastic weight averaging applied after the
fact: Izmailov et al., UAI 2018) and write the result as OUT/model.zip with the run's train.json,
for validate.py. Our own zips, read with SB3's loader.

Run: python studies/zoo-recipe/average.py models/zoo/highway-fast-dqn/seed-0 /work/zoo-exp/avg/seed-0 --from-step 14000
"""

from __future__ import annotations

import argparse
import re
import shutil
from pathlib import Path

import torch
from stable_baselines3 import DQN


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--from-step", type=int, required=True, help="average the checkpoints from this step on")
    args = parser.parse_args()
    paths = sorted((p for p in args.run.glob("checkpoints/step_*_steps.zip")
                    if int(re.search(r"_(\d+)_steps", p.name)[1]) >= args.from_step),
                   key=lambda p: int(re.search(r"_(\d+)_steps", p.name)[1]))
    models = [DQN.load(p, device="cpu") for p in paths]
    states = [m.policy.state_dict() for m in models]
    mean = {k: torch.stack([s[k].float() for s in states]).mean(0) for k in states[0]}
    models[-1].policy.load_state_dict(mean)
    args.out.mkdir(parents=True, exist_ok=True)
    models[-1].save(args.out / "model.zip")
    shutil.copy(args.run / "train.json", args.out / "train.json")
    print(f"averaged {len(paths)} checkpoints: {', '.join(p.name for p in paths)}")


if __name__ == "__main__":
    main()
