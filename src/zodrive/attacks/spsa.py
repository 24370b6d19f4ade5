"""SPSA: simultaneous-perturbation gradient estimate with Rademacher directions and Adam.

Spall, "Multivariate stochastic approximation using a simultaneous perturbation gradient
approximation", IEEE TAC 1992; as an attack: Uesato, O'Donoghue, van den Oord, Kohli,
"Adversarial Risk and the Dangers of Evaluating Against Weak Attacks", ICML 2018.

g = (1 / (2 mu q)) sum_k [f(x + mu v_k) - f(x - mu v_k)] v_k, v_k in {-1, +1}^d, then an
Adam step with learning rate `step_size` (torch.optim.Adam) and projection.

Queries per environment step: at most T * (2q + 1).
"""

from __future__ import annotations

import numpy as np
import torch

from zodrive.attacks.base import GradientEstimateAttack


class SPSA(GradientEstimateAttack):
    name = "spsa"
    reference = "Spall 1992; Uesato et al., ICML 2018"
    antithetic = True

    def directions(self, rows: np.ndarray, dim: int, mask: np.ndarray) -> np.ndarray:
        signs = np.array([-1.0, 1.0])
        return self.draw(rows, lambda g: g.choice(signs, size=(self.n_directions, dim))) * mask

    def start(self, x0: np.ndarray) -> None:
        self._param = torch.nn.Parameter(torch.from_numpy(x0.astype(np.float32).copy()))
        self._adam = torch.optim.Adam([self._param], lr=self.step_size)

    def update(self, x: np.ndarray, g: np.ndarray, rows: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            self._param[rows] = torch.from_numpy(x.astype(np.float32))
        grad = torch.zeros_like(self._param)
        grad[rows] = torch.from_numpy(g.astype(np.float32))
        self._param.grad = grad
        self._adam.step()
        return self._param.detach()[rows].numpy().copy()
