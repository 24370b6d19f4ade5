"""A probe (issue 23, item 1; not a product command): the fitted start of `attack-train --pretrain-rounds`
with a second goal where the target is out of reach. Its loss is the target's margin loss (FASTER) plus
`--avoid-weight` times the margin loss of keeping the victim off `--avoid` (SLOWER). Why: under the committed
fitted start dqn-robust brakes on 15.3 % of steps (tuning seeds), under random search on 11.1 %; braking
delays the crash. Runs `attack_train` with that objective in place of the default one; nothing else changes.

    python studies/learned-adversary/pilots/fallback/fit.py MODEL EPS OUT [--avoid-weight W] [--seed S]

With --avoid-weight 1 this is `zodrive attack-train MODEL --eps EPS --steps 0 --pretrain-rounds 4 --pretrain-episodes
10 --reward horizon --target FASTER,not:SLOWER` (the product's form of it, which gives the same model.zip, policy
bytes equal); the probe stays for the weight.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import torch

import zodrive.training.adversary as adversary
from zodrive.training.amortized import Pretrain
from zodrive.attacks.objectives import DiscreteAvoid, DiscreteTargeted
from zodrive.envs import load_preset


@dataclass(frozen=True)
class Fallback(DiscreteTargeted):
    """FASTER's margin loss plus `avoid_weight` times SLOWER's avoid loss; success is still FASTER."""

    avoid: int = 4
    avoid_weight: float = 1.0

    def loss(self, out: torch.Tensor, clean: torch.Tensor) -> torch.Tensor:
        off = DiscreteAvoid(weight=self.weight, avoid=self.avoid, kappa=self.kappa).loss(out, clean)
        return super().loss(out, clean) + self.avoid_weight * off


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("model")
    p.add_argument("eps", type=float)
    p.add_argument("out", type=Path)
    p.add_argument("--avoid-weight", type=float, default=1.0)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args()
    from zodrive.attacks import spec as spec_module

    plain = spec_module.AttackSpec.objective

    def objective(self, *args, **kwargs):  # the fitted start's objective, with the second goal
        base = plain(self, *args, **kwargs)
        return Fallback(weight=base.weight, target=base.target, kappa=base.kappa, avoid_weight=a.avoid_weight)

    spec_module.AttackSpec.objective = objective
    adversary.attack_train(a.model, load_preset("discrete"), a.eps, 0, a.out, seed=a.seed, reward="horizon",
                           pretrain=Pretrain(rounds=4, episodes=10), force=True, progress_bar=False)
    print((a.out / "train.json").read_text())


if __name__ == "__main__":
    main()
