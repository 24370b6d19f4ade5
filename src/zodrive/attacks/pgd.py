"""WHITE-BOX baselines (not black-box): PGD and FGSM with the victim's exact gradient.

Madry, Makelov, Schmidt, Tsipras, Vladu. "Towards Deep Learning Models Resistant to
Adversarial Attacks", ICLR 2018 (PGD); Goodfellow, Shlens, Szegedy. "Explaining and
Harnessing Adversarial Examples", ICLR 2015 (FGSM); Huang et al. 2017 for RL policies.

The same driver, objective and projection as the black-box attacks, and the same signed
step as ZO-SignSGD, with the gradient read from the network instead of estimated: the
ceiling for the black-box attacks. They need a victim with `differentiable` access (SB3
models); a plain query function is refused.

Queries per environment step: PGD at most T (one forward+backward per iteration, the clean
query being the first); FGSM 2 (the gradient at x0 and a check of x0 - eps * sign(grad)).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from zodrive.attacks.base import Attack, AttackResult, reads_all_but
from zodrive.attacks.objectives import Objective
from zodrive.attacks.oracle import QueryOracle
from zodrive.attacks.threat import ThreatModel


class PGD(Attack):
    name = "pgd"
    black_box = False
    reads = reads_all_but("n_directions", "mu")
    reference = "Madry et al., ICLR 2018 (white-box)"
    _unstick = False  # set per call from the objective (`Objective.flat_at_clean`)

    def queries_per_run(self, steps: int | None = None) -> int:
        return steps or self.steps

    def init(self, x0: np.ndarray, mask: np.ndarray) -> np.ndarray:
        self._x0, self._mask = x0, mask
        return x0.copy()

    def step(self, k: int, cand: np.ndarray, f: np.ndarray, rows: np.ndarray, grad: np.ndarray | None) -> np.ndarray:
        x = cand[:, 0]
        full = grad + 2 * self.l2_weight * (x - self._x0[rows])
        direction = np.sign(full) * self._mask
        flat = ~direction.any(axis=1) if self._unstick else np.zeros(len(rows), dtype=bool)
        if flat.any():  # the objective's zero gradient at the clean point would never move: a random signed
            # step instead, as Madry et al.'s random start does
            direction[flat] = self.draw(rows[flat], lambda g: g.choice((-1.0, 1.0), size=x.shape[1])) * self._mask
        return x - self._step() * direction

    def perturb(self, x0: np.ndarray, oracle: QueryOracle, objective: Objective, *, trace: bool = False
                ) -> AttackResult:
        self._unstick = objective.flat_at_clean
        return super().perturb(x0, oracle, objective, trace=trace)

    def _step(self) -> float:
        return self.step_size


class FGSM(PGD):
    """One signed-gradient step of size eps (PGD with T = 2 and step = eps)."""

    name = "fgsm"
    reads = reads_all_but("steps", "n_directions", "mu", "step_size", "patience")
    reference = "Goodfellow et al., ICLR 2015 (white-box)"

    def __init__(self, threat: ThreatModel, **kwargs: Any) -> None:
        super().__init__(threat, **kwargs)
        self.steps = 2  # gradient at x0, then evaluate x0 - eps * sign(grad)

    def _step(self) -> float:
        return self.threat.eps
