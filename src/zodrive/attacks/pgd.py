"""WHITE-BOX baselines (not black-box): PGD and FGSM with the victim's exact gradient.

Madry, Makelov, Schmidt, Tsipras, Vladu. "Towards Deep Learning Models Resistant to
Adversarial Attacks", ICLR 2018 (PGD); Goodfellow, Shlens, Szegedy. "Explaining and
Harnessing Adversarial Examples", ICLR 2015 (FGSM); Huang et al. 2017 for RL policies.

They are the ceiling for the black-box attacks: the same objective and projection, with
the gradient read from the network instead of estimated. They need a victim with
`differentiable` access (SB3 models); a plain query function is refused.

Queries per environment step: PGD at most 1 + T (one forward+backward per iteration);
FGSM 2 (the gradient at x0 and a check of the result).
"""

from __future__ import annotations

import numpy as np
import torch

from zodrive.attacks.base import Attack, AttackResult, Best
from zodrive.attacks.objectives import Objective
from zodrive.attacks.oracle import QueryBudgetExhausted, QueryOracle
from zodrive.attacks.threat import distortion


class PGD(Attack):
    name = "pgd"
    black_box = False
    reference = "Madry et al., ICLR 2018 (white-box)"

    def queries_per_step(self) -> int:
        return 1 + self.steps

    def _loss(self, x0: np.ndarray, clean: np.ndarray, objective: Objective, rows: np.ndarray):
        clean_t = torch.from_numpy(clean[rows])
        x0_t = torch.from_numpy(x0[rows].reshape(rows.size, -1).astype(np.float32))

        def fn(out: torch.Tensor, x: torch.Tensor | None = None) -> torch.Tensor:
            return objective.loss(out[:, None], clean_t)[:, 0]

        return fn, x0_t

    def perturb(
        self, x0: np.ndarray, oracle: QueryOracle, objective: Objective, *, trace: bool = False
    ) -> AttackResult:
        n, shape = len(x0), x0.shape[1:]
        mask = self.threat.mask(shape)
        clean, already = self.clean_query(x0, oracle, objective)
        per_row = np.ones(n, dtype=np.int64)
        iterations = np.zeros(n, dtype=np.int64)
        best = Best(x0, clean, already)
        active = ~already if self.early_stop else np.ones(n, dtype=bool)
        x = x0.astype(np.float32).copy()
        records: list[dict[str, np.ndarray]] = []
        for k in range(self.steps):
            rows = np.flatnonzero(active)
            if rows.size == 0:
                break
            fn, _ = self._loss(x0, clean, objective, rows)
            try:
                out, grad = oracle.gradient(x[rows], fn)
            except QueryBudgetExhausted:
                break
            per_row[rows] += 1
            iterations[rows] += 1
            l1, l2, ok = self.objective_values(x[rows][:, None], x0[rows], out[:, None], clean[rows], objective)
            f = (l1 + self.l2_weight * l2)[:, 0]
            best.offer(rows, x[rows], out, f, ok[:, 0])
            if trace:
                rec = {"l1": np.full(n, np.nan), "l2": np.full(n, np.nan)}
                rec["l1"][rows], rec["l2"][rows] = l1[:, 0], l2[:, 0]
                records.append(rec)
            if self.early_stop:
                active[rows[ok[:, 0]]] = False
            full_grad = grad + 2 * self.l2_weight * (x[rows] - x0[rows])
            x[rows] = self.threat.project(x[rows] - self._step() * np.sign(full_grad) * mask, x0[rows])
        linf, l2n = distortion(best.x, x0)
        return AttackResult(
            x_adv=best.x.astype(x0.dtype), success=best.ok & ~already, already=already,
            iterations=iterations, queries=per_row, linf=linf, l2=l2n,
            adv_outputs=best.out, clean_outputs=clean, trace=records,
        )

    def _step(self) -> float:
        return self.step_size


class FGSM(PGD):
    """One signed-gradient step of size eps (PGD with T = 1 and step = eps), then a check."""

    name = "fgsm"
    reference = "Goodfellow et al., ICLR 2015 (white-box)"

    def __init__(self, threat, **kwargs) -> None:  # type: ignore[no-untyped-def]
        kwargs["steps"] = 2  # gradient at x0, then evaluate x0 - eps * sign(grad)
        kwargs["early_stop"] = True
        super().__init__(threat, **kwargs)

    def queries_per_step(self) -> int:
        return 3

    def _step(self) -> float:
        return self.threat.eps
