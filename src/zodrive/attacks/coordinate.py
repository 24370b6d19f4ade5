"""Coordinate-wise finite differences (ZOO-style) with a signed step.

Chen, Zhang, Sharma, Yi, Hsieh. "ZOO: Zeroth Order Optimization based Black-box Attacks
to Deep Neural Networks without Training Substitute Models", AISec 2017.

Each iteration picks q coordinates e_i at random (without replacement, among the
perturbable ones), estimates g_i = [f(x + mu e_i) - f(x - mu e_i)] / (2 mu) and moves those
coordinates by -step_size * sign(g_i).

Queries per environment step: at most T * (2q + 1).
"""

from __future__ import annotations

import numpy as np

from zodrive.attacks.base import GradientEstimateAttack


class CoordinateFD(GradientEstimateAttack):
    name = "coordinate-fd"
    reference = "Chen et al., ZOO, AISec 2017"
    antithetic = True
    unit_directions = True

    def directions(self, rows: np.ndarray, dim: int, mask: np.ndarray) -> np.ndarray:
        free = np.flatnonzero(mask)
        q = min(self.n_directions, free.size)
        n = len(rows)
        u = np.zeros((n, q, dim))  # q <= number of free coordinates: no wasted queries
        picks = np.argsort(self.draw(rows, lambda g: g.random(free.size)), axis=1)[:, :q]
        rows = np.repeat(np.arange(n), q)
        u[rows, np.tile(np.arange(q), n), free[picks].reshape(-1)] = 1.0
        return u

    def update(self, x: np.ndarray, g: np.ndarray, rows: np.ndarray) -> np.ndarray:
        return x - self.step_size * np.sign(g)
