"""Random search (Square-attack style) on the vertices of the L-inf ball.

Andriushchenko, Croce, Flammarion, Hein. "Square Attack: a query-efficient black-box
adversarial attack via random search", ECCV 2020.

Starts from a random vertex perturbation (+-eps per free coordinate). Each iteration
proposes q candidates, each re-drawing the signs of a random subset of coordinates (a
fraction that shrinks over iterations, as Square's schedule), queries them in one batch and
moves to the best if it lowers the objective. With the L2 norm, candidates are projected.

Queries per environment step: at most 2 + T * q (the clean observation, the starting
vertex, q proposals per iteration).
"""

from __future__ import annotations

import numpy as np

from zodrive.attacks.base import Attack, reads_all_but


class RandomSearch(Attack):
    name = "random-search"
    reads = reads_all_but("mu", "step_size")  # it moves between vertices: no finite differences, no step
    reference = "Andriushchenko et al., Square Attack, ECCV 2020"
    p_init: float = 0.3  # initial fraction of coordinates re-drawn per proposal
    # on one-hot outputs its objective is a function of the decision alone (0 at the goal, 1 + kappa elsewhere;
    # a fallback target adds a level) and it moves only to a point that lowers it: a decision-based search
    on_decisions = True

    def queries_per_run(self, steps: int | None = None) -> int:
        return 2 + (steps or self.steps) * self.n_directions

    def _fraction(self, k: int) -> float:
        return max(self.p_init * 0.5 ** int(np.log2(1 + 10 * k / self.steps)), 1.0 / 25)

    def _vertices(self, g: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
        eps = self.threat.eps
        return g.choice(np.array([-eps, eps], dtype=np.float32), size=shape)

    def init(self, x0: np.ndarray, mask: np.ndarray) -> np.ndarray:
        self._x0 = x0
        return x0 + self.draw(np.arange(len(x0)), lambda g: self._vertices(g, x0.shape[1:])) * mask

    def propose(self, k: int, x: np.ndarray, rows: np.ndarray, mask: np.ndarray) -> np.ndarray:
        q, dim = self.n_directions, x.shape[1]
        fraction = self._fraction(k)

        def draw(g: np.random.Generator) -> np.ndarray:  # which coordinates change, then to what
            change = (g.random((q, dim)) < fraction) & (mask > 0)
            return np.where(change, self._vertices(g, change.shape), np.nan)

        fresh = self.draw(rows, draw)
        current = (x - self._x0[rows])[:, None]
        return self._x0[rows, None] + np.where(np.isnan(fresh), current, fresh)

    def step(self, k: int, cand: np.ndarray, f: np.ndarray, rows: np.ndarray, grad: np.ndarray | None) -> np.ndarray:
        pick = 1 + f[:, 1:].argmin(axis=1)
        ar = np.arange(len(rows))
        improved = f[ar, pick] < f[:, 0]
        return np.where(improved[:, None], cand[ar, pick], cand[:, 0])
