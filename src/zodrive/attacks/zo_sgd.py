"""ZO-SGD: zeroth-order stochastic gradient descent with the raw (not signed) estimate.

Ghadimi and Lan, "Stochastic first- and zeroth-order methods for nonconvex stochastic
programming", SIAM J. Optim. 2013; as used for attacks in Liu et al., ICLR 2019.

Same estimator as ZO-SignSGD, g = (d / (mu q)) sum_k [f(x + mu u_k) - f(x)] u_k, and the
step x <- Proj(x - step_size * g).

Queries per environment step: at most T * (q + 1).
"""

from __future__ import annotations

import numpy as np

from zodrive.attacks.base import GradientEstimateAttack, unit_sphere


class ZOSGD(GradientEstimateAttack):
    name = "zo-sgd"
    reference = "Ghadimi & Lan, SIAM J. Optim. 2013; Liu et al., ICLR 2019"
    unit_directions = True

    def directions(self, rows: np.ndarray, dim: int, mask: np.ndarray) -> np.ndarray:
        return unit_sphere(self.normals(rows, (self.n_directions, dim)), mask)

    def update(self, x: np.ndarray, g: np.ndarray, rows: np.ndarray) -> np.ndarray:
        return x - self.step_size * g
