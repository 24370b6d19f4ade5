"""HopSkipJump, decision-based: the boundary attack adapted to a fixed eps-ball of a small observation.

Chen, Jordan, Wainwright. "HopSkipJumpAttack: A Query-Efficient Decision-Based Adversarial Attack",
IEEE S&P 2020 (after Brendel et al., "Decision-Based Adversarial Attacks", ICLR 2018; cf. Cheng et al.,
"Sign-OPT", ICLR 2020, the same sign-of-the-decision idea).

It reads one bit per queried point: whether the victim's decision meets the goal (`Objective.success`:
it took the target, avoided the action, or left its clean action). Run it with `access: decision`, where
the oracle returns only the action taken (one-hot), to show that this bit is all it needs. The only other
thing it reads is the objective's value of a point that misses the goal, and only to choose which miss
is fed when a step finds no success (the driver's rule). Under decision access that value depends only on
the decision too.

HSJA starts from a point that already succeeds, often far away, and walks along the decision boundary
toward the clean point to shrink the distance. zodrive's threat model allows neither part. Every point
the victim sees lies in the eps-ball ∩ the observation box with the frozen features (presence) fixed, so
the attack cannot start far outside. And the ball is fixed: the goal is success inside it, not the
smallest distance. So the attack runs in two parts, each a phase of the one driver loop
(`attacks.base`) with q = n_directions queries per iteration:

1. search: until some queried point succeeds, q fresh random vertices of the ball per iteration,
   independent draws (as random search's starting vertex). A 0/1 signal gives nothing to climb before
   the first success. Random search on a flat objective re-draws a few coordinates of one failing
   vertex, which only samples its neighbours; independent draws cover more of the ball. With early stop
   (the default) a step ends at its first success, so this part decides the success rate.
2. boundary (with --no-early-stop, only after a success): HSJA's iteration from the successful point x,
   each stage one iteration:
   - line: q points on the segment from x0 to x (alpha = j / (q + 1)). The successful point nearest x0
     is kept. This is HSJA's binary search done as a grid, so that it is one batch.
   - probe: q points x + delta u, where u is random signs on the free coordinates (L2: random unit
     directions) and delta = 2 ||x - x0|| / (q + 1), twice the line's resolution, so the probes straddle
     the boundary that the line located. The normal of the boundary is estimated by HSJA's
     baseline-corrected Monte-Carlo sign estimate: v = sum_j (phi_j - mean phi) u_j, where phi = +-1
     says whether the goal was met.
   - jump: q points x + xi 2^(-j/2) sign(v) (L2: v / ||v||), where xi = ||x - x0|| / sqrt(t) is HSJA's
     step size at iteration t. The largest step that succeeds is kept (its geometric step search), and
     the next line starts from it. If no step succeeds, the attack probes again.
   The point fed is the queried successful point nearest the clean one (L-inf, or L2 with norm l2).

Queries per environment step: at most 2 + T * q: the clean observation, the starting vertex, and q per
iteration. Each step lands on a point already queried, so the next base point costs nothing.
"""

from __future__ import annotations

import numpy as np

from zodrive.attacks.base import Attack, reads_all_but

SEARCH, LINE, PROBE, JUMP = 0, 1, 2, 3
"""A row's phase: searching for a first success, then HSJA's line search, normal estimate and jump."""


class HopSkipJump(Attack):
    name = "hsja"
    # no finite differences (mu), no step of its own size (step_size), no distance term (it ranks successful
    # points by their distance itself): the objective's value only ranks the misses (loss, kappa, a fallback target)
    reads = reads_all_but("mu", "step_size", "l2_weight", "weight")
    reference = "Chen, Jordan & Wainwright, HopSkipJumpAttack, IEEE S&P 2020"
    on_decisions = True

    def queries_per_run(self, steps: int | None = None) -> int:
        return 2 + (steps or self.steps) * self.n_directions

    # -- geometry in the threat model's norm -------------------------------------------
    def _distance(self, delta: np.ndarray) -> np.ndarray:
        """||delta|| along the last axis in the budget's norm (float64)."""
        delta = np.asarray(delta, dtype=np.float64)
        if self.threat.norm == "l2":
            return np.sqrt((delta * delta).sum(axis=-1))
        return np.abs(delta).max(axis=-1)

    def _vertices(self, g: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
        eps = self.threat.eps
        return g.choice(np.array([-eps, eps], dtype=np.float32), size=shape)

    def _directions(self, g: np.random.Generator, shape: tuple[int, ...], mask: np.ndarray) -> np.ndarray:
        """Probe directions of unit size in the norm, zero on frozen coordinates: signs (L-inf) or unit vectors (L2)."""
        if self.threat.norm == "l2":
            u = g.standard_normal(shape) * mask
            return (u / np.maximum(np.sqrt((u * u).sum(axis=-1, keepdims=True)), 1e-12)).astype(np.float32)
        return (g.choice(np.array([-1.0, 1.0], dtype=np.float32), size=shape) * mask).astype(np.float32)

    def _heading(self, v: np.ndarray) -> np.ndarray:
        """The jump's direction from the normal's estimate: its signs (L-inf) or its unit vector (L2)."""
        if self.threat.norm == "l2":
            return (v / max(float(np.sqrt((v.astype(np.float64) ** 2).sum())), 1e-12)).astype(np.float32)
        return np.sign(v).astype(np.float32)

    # -- the driver's hooks ----------------------------------------------------------------
    def init(self, x0: np.ndarray, mask: np.ndarray) -> np.ndarray:
        n, dim = x0.shape
        self._x0 = x0
        self._phase = np.full(n, SEARCH, dtype=np.int8)
        self._v = np.zeros((n, dim), dtype=np.float32)  # per row, the last estimate of the boundary's normal
        self._t = np.zeros(n, dtype=np.int64)  # per row, HSJA iterations done (line searches)
        self._ok = np.zeros((n, 0), dtype=bool)
        return x0 + self.draw(np.arange(n), lambda g: self._vertices(g, (dim,))) * mask

    def propose(self, k: int, x: np.ndarray, rows: np.ndarray, mask: np.ndarray) -> np.ndarray:
        q, dim = self.n_directions, x.shape[1]
        x0 = self._x0[rows]
        dist = self._distance(x - x0)
        out = np.empty((len(rows), q, dim), dtype=np.float32)
        self._u = np.zeros((len(rows), q, dim), dtype=np.float32)
        for i, r in enumerate(rows):  # each row from its own stream, in its own phase
            phase, g = self._phase[r], self._rngs[r]
            if phase == SEARCH:
                out[i] = x0[i] + self._vertices(g, (q, dim)) * mask
            elif phase == LINE:
                alpha = (np.arange(1, q + 1, dtype=np.float32) / np.float32(q + 1))[:, None]
                out[i] = x0[i] + alpha * (x[i] - x0[i])
            elif phase == PROBE:
                self._u[i] = self._directions(g, (q, dim), mask)
                out[i] = x[i] + np.float32(2.0 * dist[i] / (q + 1)) * self._u[i]
            else:
                xi = dist[i] / np.sqrt(max(int(self._t[r]), 1)) * 2.0 ** (-np.arange(q) / 2.0)
                out[i] = x[i] + xi.astype(np.float32)[:, None] * self._heading(self._v[r])
        return out

    def keep_proposals(self, keep: np.ndarray) -> None:
        self._u = self._u[keep]

    def observe(self, rows: np.ndarray, ok: np.ndarray) -> None:
        self._ok = ok

    def merit(self, f: np.ndarray, cand: np.ndarray, x0: np.ndarray, ok: np.ndarray) -> np.ndarray:
        """Successful points rank by their distance to the clean point; misses by the objective."""
        return np.where(ok, self._distance(cand - x0[:, None]), f)

    def step(self, k: int, cand: np.ndarray, f: np.ndarray, rows: np.ndarray, grad: np.ndarray | None) -> np.ndarray:
        """The next base point of each row, always one of its queried candidates (read: `self._ok`)."""
        ok, nxt = self._ok, cand[:, 0].copy()
        dist = self._distance(cand - self._x0[rows, None])
        for i, r in enumerate(rows):
            phase = self._phase[r]
            if phase != SEARCH and not ok[i, 0]:  # the base point always succeeds past the search (a safeguard)
                phase = self._phase[r] = SEARCH
            if phase in (SEARCH, LINE):
                hits = np.flatnonzero(ok[i])
                if hits.size:  # the successful point nearest the clean one (the first on a tie)
                    nxt[i] = cand[i, hits[np.argmin(dist[i, hits])]]
                    self._t[r] += phase == LINE
                    self._phase[r] = LINE if phase == SEARCH else PROBE
            elif phase == PROBE:
                phi = np.where(ok[i, 1:], 1.0, -1.0)
                weights = phi - phi.mean() if 0 < ok[i, 1:].sum() < len(phi) else phi
                self._v[r] = (weights[:, None] * self._u[i]).sum(axis=0)
                self._phase[r] = JUMP
            else:
                hits = np.flatnonzero(ok[i, 1:])
                if hits.size:  # the largest step that still succeeds
                    nxt[i] = cand[i, 1 + hits[0]]
                    self._phase[r] = LINE
                else:
                    self._phase[r] = PROBE
        return nxt
