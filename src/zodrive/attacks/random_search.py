"""Random search (Square-attack style) on the vertices of the L-inf ball.

Andriushchenko, Croce, Flammarion, Hein. "Square Attack: a query-efficient black-box
adversarial attack via random search", ECCV 2020.

Starts from a random vertex perturbation (+-eps per free coordinate). Each iteration
proposes q candidates, each re-drawing the signs of a random subset of coordinates (a
fraction that shrinks over iterations, as Square's schedule), queries them in one batch and
keeps the best if it lowers the objective. With the L2 norm, candidates are projected.

Queries per environment step: at most 2 + T * q.
"""

from __future__ import annotations

import numpy as np

from zodrive.attacks.base import Attack, AttackResult, Best
from zodrive.attacks.objectives import Objective
from zodrive.attacks.oracle import QueryBudgetExhausted, QueryOracle
from zodrive.attacks.threat import distortion


class RandomSearch(Attack):
    name = "random-search"
    reference = "Andriushchenko et al., Square Attack, ECCV 2020"
    p_init: float = 0.3  # initial fraction of coordinates re-drawn per proposal

    def queries_per_step(self) -> int:
        return 2 + self.steps * self.n_directions

    def _fraction(self, k: int) -> float:
        return max(self.p_init * 0.5 ** int(np.log2(1 + 10 * k / self.steps)), 1.0 / 25)

    def perturb(
        self, x0: np.ndarray, oracle: QueryOracle, objective: Objective, *, trace: bool = False
    ) -> AttackResult:
        n, shape = len(x0), x0.shape[1:]
        dim = int(np.prod(shape))
        mask = self.threat.mask(shape).reshape(-1)
        flat0 = x0.reshape(n, dim)
        per_row = np.ones(n, dtype=np.int64)
        iterations = np.zeros(n, dtype=np.int64)
        clean, already = self.clean_query(x0, oracle, objective)
        best = Best(x0, clean, already)
        active = ~already if self.early_stop else np.ones(n, dtype=bool)
        records: list[dict[str, np.ndarray]] = []
        rows = np.flatnonzero(active)
        eps = self.threat.eps
        delta = self.rng.choice(np.array([-eps, eps]), size=(n, dim)) * mask
        x = self.threat.project((flat0 + delta).reshape(n, *shape), x0).reshape(n, dim)
        f_cur = np.full(n, np.inf)
        try:
            if rows.size:
                out = oracle(x[rows].reshape(rows.size, *shape)).reshape(rows.size, 1, -1)
                per_row[rows] += 1
                l1, l2, ok = self.objective_values(x[rows].reshape(rows.size, 1, *shape), x0[rows], out, clean[rows], objective)
                f_cur[rows] = (l1 + self.l2_weight * l2)[:, 0]
                best.offer(rows, x[rows].reshape(rows.size, *shape), out[:, 0], f_cur[rows], ok[:, 0])
                if self.early_stop:
                    active[rows[ok[:, 0]]] = False
            for k in range(self.steps):
                rows = np.flatnonzero(active)
                if rows.size == 0:
                    break
                q = self.n_directions
                change = (self.rng.random((rows.size, q, dim)) < self._fraction(k)) * mask
                signs = self.rng.choice(np.array([-eps, eps]), size=(rows.size, q, dim))
                cand_delta = np.where(change > 0, signs, (x[rows] - flat0[rows])[:, None])
                cand = self.threat.project(
                    (flat0[rows, None] + cand_delta).reshape(rows.size * q, *shape),
                    np.repeat(x0[rows], q, axis=0),
                ).reshape(rows.size, q, dim)
                out = oracle(cand.reshape(rows.size * q, *shape)).reshape(rows.size, q, -1)
                per_row[rows] += q
                iterations[rows] += 1
                l1, l2, ok = self.objective_values(cand.reshape(rows.size, q, *shape), x0[rows], out, clean[rows], objective)
                f = l1 + self.l2_weight * l2
                pick = f.argmin(axis=1)
                ar = np.arange(rows.size)
                f_pick, ok_pick = f[ar, pick], ok[ar, pick]
                best.offer(rows, cand[ar, pick].reshape(rows.size, *shape), out[ar, pick], f_pick, ok_pick)
                improved = f_pick < f_cur[rows]
                x[rows[improved]] = cand[ar, pick][improved]
                f_cur[rows[improved]] = f_pick[improved]
                if trace:
                    rec = {"l1": np.full(n, np.nan), "l2": np.full(n, np.nan)}
                    rec["l1"][rows], rec["l2"][rows] = l1[ar, pick], l2[ar, pick]
                    records.append(rec)
                if self.early_stop:
                    active[rows[ok_pick]] = False
        except QueryBudgetExhausted:
            pass
        linf, l2n = distortion(best.x, x0)
        return AttackResult(
            x_adv=best.x.astype(x0.dtype), success=best.ok & ~already, already=already,
            iterations=iterations, queries=per_row, linf=linf, l2=l2n,
            adv_outputs=best.out, clean_outputs=clean, trace=records,
        )
