"""The attack interface and the shared zeroth-order loop.

An attack turns clean observations `x0` (N environments at once) into perturbed ones
inside a `ThreatModel`, talking to the victim only through a `QueryOracle`. Gradient-
estimating attacks (ZO-SignSGD, ZO-SGD, NES, SPSA, coordinate differences) share one loop
and differ only in how they draw directions and take a step, as in foolbox/ART:

    for k in 0..T-1:
        query [x_k, x_k + mu*u_1, ..., x_k + mu*u_q]   (one victim call for all N envs)
        keep the best iterate so far (successful first, then lowest objective)
        stop rows that succeeded (early_stop)
        g = estimate(f, u);  x_{k+1} = project(update(x_k, g))

The objective is the paper's Eq. 8: L1 (from `objectives`) + l2_weight * ||x - x0||^2.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
import torch

from zodrive.attacks.objectives import Objective
from zodrive.attacks.oracle import QueryBudgetExhausted, QueryOracle
from zodrive.attacks.threat import ThreatModel, distortion
from zodrive.errors import ZodriveError


@dataclass
class AttackResult:
    """What one attacked environment step produced, per environment row."""

    x_adv: np.ndarray            # (N, *obs) the observation the policy will receive
    success: np.ndarray          # (N,) goal met on x_adv
    already: np.ndarray          # (N,) goal already met on the clean observation
    iterations: np.ndarray       # (N,) iterations run
    queries: np.ndarray          # (N,) victim queries spent on this row
    linf: np.ndarray             # (N,) ||x_adv - x0||_inf
    l2: np.ndarray               # (N,) ||x_adv - x0||_2
    adv_outputs: np.ndarray      # (N, k) victim outputs on x_adv (seen by the attacker)
    clean_outputs: np.ndarray    # (N, k) victim outputs on x0
    trace: list[dict[str, np.ndarray]] = field(default_factory=list)  # per iteration: l1, l2


class Attack(abc.ABC):
    """Base class: validated hyperparameters, a seeded generator, `perturb`."""

    name: ClassVar[str]
    black_box: ClassVar[bool] = True
    reference: ClassVar[str] = ""

    def __init__(
        self,
        threat: ThreatModel,
        *,
        steps: int = 100,
        n_directions: int = 20,
        mu: float = 0.005,
        step_size: float = 0.01,
        l2_weight: float = 0.0,
        early_stop: bool = True,
        seed: int = 0,
    ) -> None:
        if not isinstance(steps, (int, np.integer)) or steps < 1:
            raise ZodriveError(f"steps (T) must be an integer >= 1, not {steps}")
        if not isinstance(n_directions, (int, np.integer)) or n_directions < 1:
            raise ZodriveError(f"n_directions (q) must be an integer >= 1, not {n_directions}")
        if not mu > 0:
            raise ZodriveError(f"mu must be > 0, not {mu}")
        if not step_size > 0:
            raise ZodriveError(f"step_size must be > 0, not {step_size}")
        if not l2_weight >= 0:
            raise ZodriveError(f"l2_weight must be >= 0, not {l2_weight}")
        self.threat = threat
        self.steps = int(steps)
        self.n_directions = int(n_directions)
        self.mu = float(mu)
        self.step_size = float(step_size)
        self.l2_weight = float(l2_weight)
        self.early_stop = bool(early_stop)
        self.seed = seed
        self.rng = np.random.default_rng(seed)

    def reseed(self, seed: int) -> None:
        """Restart the attack's random stream (e.g. per episode, for reproducible episodes)."""
        self.rng = np.random.default_rng(seed)

    @abc.abstractmethod
    def queries_per_step(self) -> int:
        """Upper bound on victim queries per environment step (the docstring's formula)."""

    @abc.abstractmethod
    def perturb(
        self, x0: np.ndarray, oracle: QueryOracle, objective: Objective, *, trace: bool = False
    ) -> AttackResult:
        """Attack clean observations `x0` (N, *obs); see `AttackResult`."""

    # -- shared pieces -------------------------------------------------------------
    def objective_values(
        self, x: np.ndarray, x0: np.ndarray, out: np.ndarray, clean: np.ndarray, objective: Objective
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """L1 (A, M), L2 (A, M) and success (A, M) of candidates x (A, M, *obs)."""
        out_t, clean_t = torch.from_numpy(out), torch.from_numpy(clean)
        l1 = objective.loss(out_t, clean_t).numpy().astype(np.float64)
        diff = (x - x0[:, None]).reshape(x.shape[0], x.shape[1], -1).astype(np.float64)
        l2 = (diff**2).sum(axis=-1)
        ok = objective.success(out_t, clean_t).numpy()
        return l1, l2, ok

    def clean_query(self, x0: np.ndarray, oracle: QueryOracle, objective: Objective) -> tuple[np.ndarray, np.ndarray]:
        """Outputs on the clean observations (one query each) and where the goal is met."""
        clean = oracle(x0).astype(np.float32)
        already = objective.already(torch.from_numpy(clean)).numpy()
        return clean, already


class Best:
    """Tracks, per row, the best iterate: successful beats unsuccessful, then lower f."""

    def __init__(self, x0: np.ndarray, clean: np.ndarray, already: np.ndarray) -> None:
        n = len(x0)
        self.x = x0.copy()
        self.out = clean.copy()
        self.ok = already.copy()
        self.f = np.full(n, np.inf)

    def offer(self, rows: np.ndarray, x: np.ndarray, out: np.ndarray, f: np.ndarray, ok: np.ndarray) -> None:
        better = (ok & ~self.ok[rows]) | ((ok == self.ok[rows]) & (f < self.f[rows]))
        take = rows[better]
        self.x[take], self.out[take] = x[better], out[better]
        self.f[take], self.ok[take] = f[better], ok[better]


class GradientEstimateAttack(Attack):
    """The shared loop for attacks that estimate a gradient from finite differences."""

    antithetic: ClassVar[bool] = False  # central differences f(x+mu u) - f(x-mu u)
    unit_directions: ClassVar[bool] = False  # E[u u^T] = I/d: scale the estimate by d

    def queries_per_step(self) -> int:
        per_iteration = 1 + self.n_directions * (2 if self.antithetic else 1)
        return 1 + self.steps * per_iteration

    @abc.abstractmethod
    def directions(self, n: int, dim: int, mask: np.ndarray) -> np.ndarray:
        """(n, q, dim) directions for n rows, zero on masked coordinates."""

    def estimate(self, f: np.ndarray, u: np.ndarray, d: int) -> np.ndarray:
        """Gradient estimate (A, dim) from objective values f (A, M) at [x, x+mu u(, x-mu u)].

        `d` is the number of perturbable coordinates (the paper's `d` in Algorithm 1).
        """
        q = u.shape[1]
        if self.antithetic:
            diff = (f[:, 1 : 1 + q] - f[:, 1 + q :]) / (2 * self.mu)
        else:
            diff = (f[:, 1:] - f[:, :1]) / self.mu
        scale = (d if self.unit_directions else 1.0) / q
        return np.einsum("aq,aqd->ad", diff, u) * scale

    def start(self, x0: np.ndarray) -> None:
        """Per-call state (e.g. an optimizer) before the first update."""

    @abc.abstractmethod
    def update(self, x: np.ndarray, g: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """One step from flattened iterates x (A, dim) with estimate g (A, dim)."""

    def perturb(
        self, x0: np.ndarray, oracle: QueryOracle, objective: Objective, *, trace: bool = False
    ) -> AttackResult:
        n, shape = len(x0), x0.shape[1:]
        dim = int(np.prod(shape))
        mask = self.threat.mask(shape).reshape(-1)
        d_free = int(mask.sum())
        per_row = np.zeros(n, dtype=np.int64)
        iterations = np.zeros(n, dtype=np.int64)
        clean, already = self.clean_query(x0, oracle, objective)
        per_row += 1
        best = Best(x0, clean, already)
        active = ~already if self.early_stop else np.ones(n, dtype=bool)
        x = x0.reshape(n, dim).astype(np.float32).copy()
        flat0 = x0.reshape(n, dim)
        self.start(x)
        records: list[dict[str, np.ndarray]] = []
        sign = np.array([1.0, -1.0], dtype=np.float32)
        for k in range(self.steps):
            rows = np.flatnonzero(active)
            if rows.size == 0:
                break
            u = self.directions(rows.size, dim, mask).astype(np.float32)
            probes = [x[rows, None] + (s * self.mu) * u for s in (sign if self.antithetic else sign[:1])]
            cand = np.concatenate([x[rows, None]] + probes, axis=1)  # (A, M, dim)
            m = cand.shape[1]
            try:
                out = oracle(cand.reshape(rows.size * m, *shape)).reshape(rows.size, m, -1)
            except QueryBudgetExhausted:
                break
            per_row[rows] += m
            iterations[rows] += 1
            l1, l2, ok = self.objective_values(
                cand.reshape(rows.size, m, *shape), x0[rows], out, clean[rows], objective
            )
            f = l1 + self.l2_weight * l2
            best.offer(rows, cand[:, 0].reshape(rows.size, *shape), out[:, 0], f[:, 0], ok[:, 0])
            if trace:
                rec_l1 = np.full(n, np.nan)
                rec_l2 = np.full(n, np.nan)
                rec_l1[rows], rec_l2[rows] = l1[:, 0], l2[:, 0]
                records.append({"l1": rec_l1, "l2": rec_l2})
            if self.early_stop:
                active[rows[ok[:, 0]]] = False
            if k == self.steps - 1:
                break
            g = self.estimate(f, u, d_free)
            stepped = self.update(x[rows], g, rows)
            x[rows] = self.threat.project(
                stepped.reshape(rows.size, *shape), flat0[rows].reshape(rows.size, *shape)
            ).reshape(rows.size, dim)
        linf, l2n = distortion(best.x, x0)
        return AttackResult(
            x_adv=best.x.astype(x0.dtype), success=best.ok & ~already, already=already,
            iterations=iterations, queries=per_row, linf=linf, l2=l2n,
            adv_outputs=best.out, clean_outputs=clean, trace=records,
        )


def unit_sphere(rng: np.random.Generator, n: int, q: int, dim: int, mask: np.ndarray) -> np.ndarray:
    """q directions per row, uniform on the unit sphere of the unmasked subspace."""
    u = rng.standard_normal((n, q, dim)) * mask
    return u / np.maximum(np.linalg.norm(u, axis=-1, keepdims=True), 1e-12)
