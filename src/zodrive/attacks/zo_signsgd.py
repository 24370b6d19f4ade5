"""ZO-SignSGD: the paper's attack (Algorithm 1, Eq. 5-8).

Liu, Chen, Chen, Hong. "signSGD via Zeroth-Order Oracle", ICLR 2019.

Gradient estimate from q random unit directions with forward differences,
    g = (d / (mu q)) * sum_k [f(x + mu u_k) - f(x)] u_k,
then a sign step x <- Proj(x - step_size * sign(g)). Objective f = L1 + l2_weight * L2.

Queries per environment step: at most T * (q + 1) (per iteration the base point and q
probes in one batch; the clean observation is iteration 0's base point); fewer with early
stopping.
"""

from __future__ import annotations

import numpy as np

from zodrive.attacks.base import GradientEstimateAttack, unit_sphere


class ZOSignSGD(GradientEstimateAttack):
    name = "zo-signsgd"
    reference = "Liu et al., signSGD via Zeroth-Order Oracle, ICLR 2019"
    unit_directions = True

    def directions(self, rows: np.ndarray, dim: int, mask: np.ndarray) -> np.ndarray:
        return unit_sphere(self.normals(rows, (self.n_directions, dim)), mask)

    def update(self, x: np.ndarray, g: np.ndarray, rows: np.ndarray) -> np.ndarray:
        return x - self.step_size * np.sign(g)
