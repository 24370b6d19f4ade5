"""Uniform random noise inside the budget: the floor every real attack must beat.

No optimization: one draw, uniform in the L-inf box (or L2 ball) of radius eps, masked and
clipped. It queries only to report its effect.

Queries per environment step: 2 (the clean observation and the noisy one).
"""

from __future__ import annotations

import numpy as np
import torch

from zodrive.attacks.base import Attack, AttackResult
from zodrive.attacks.objectives import Objective
from zodrive.attacks.oracle import QueryOracle
from zodrive.attacks.threat import distortion


class UniformNoise(Attack):
    name = "uniform-noise"
    reference = "baseline (no paper): uniform noise in the threat model"

    def queries_per_step(self) -> int:
        return 2

    def perturb(
        self, x0: np.ndarray, oracle: QueryOracle, objective: Objective, *, trace: bool = False
    ) -> AttackResult:
        clean, already = self.clean_query(x0, oracle, objective)
        x = self.threat.project(x0 + self.threat.random_delta(x0, self.rng), x0)
        out = oracle(x).astype(np.float32)
        ok = objective.success(torch.from_numpy(out)[:, None], torch.from_numpy(clean)).numpy()[:, 0]
        linf, l2 = distortion(x, x0)
        n = len(x0)
        return AttackResult(
            x_adv=x, success=ok & ~already, already=already, iterations=np.zeros(n, dtype=np.int64),
            queries=np.full(n, 2), linf=linf, l2=l2, adv_outputs=out, clean_outputs=clean,
        )
