"""NES: natural-evolution-strategies gradient estimate with antithetic Gaussian samples.

Ilyas, Engstrom, Athalye, Lin. "Black-box Adversarial Attacks with Limited Queries and
Information", ICML 2018.

g = (1 / (2 mu q)) sum_k [f(x + mu u_k) - f(x - mu u_k)] u_k with u_k ~ N(0, I), then a
signed (PGD-style) step x <- Proj(x - step_size * sign(g)).

Queries per environment step: at most T * (2q + 1).
"""

from __future__ import annotations

import numpy as np

from zodrive.attacks.base import GradientEstimateAttack


class NES(GradientEstimateAttack):
    name = "nes"
    reference = "Ilyas et al., Black-box Adversarial Attacks with Limited Queries and Information, ICML 2018"
    antithetic = True

    def directions(self, rows: np.ndarray, dim: int, mask: np.ndarray) -> np.ndarray:
        return self.normals(rows, (self.n_directions, dim)) * mask

    def update(self, x: np.ndarray, g: np.ndarray, rows: np.ndarray) -> np.ndarray:
        return x - self.step_size * np.sign(g)
