"""The attack interface and the one driver loop every attack runs in.

An attack turns clean observations `x0` (N environments at once) into perturbed ones
inside a `ThreatModel`, talking to the victim only through a `QueryOracle`. The driver
(`Attack.perturb`) owns everything attacks share, so that no attack can get it wrong:

    query x0 (the clean outputs; iteration 0's base point, never queried twice)
    x = init(x0)
    for k in 0..T-1, over the rows still active:
        candidates = [x, *propose(x)]      projected into the box and the eps-ball
        skip rows whose own per-step budget cannot pay for them; query the rest in one
        batch (a base point whose outputs are known is not queried again)
        keep the best queried point so far (successful first, then lowest objective)
        stop rows that succeeded (early_stop)
        x = project(step(candidates, objective values))

An attack only says how to start (`init`), what to query around the base point
(`propose`) and where to go next (`step`). The objective is the paper's Eq. 8:
L1 (from `objectives`) + l2_weight * ||x - x0||^2. White-box baselines (`black_box =
False`) get the exact gradient of L1 at the base point instead of probes. Two attacks are no
search and bring their own `perturb` (`search = False`): the learned adversary
(`attacks.learned`) and vertex hold (`attacks.hold`).
"""

from __future__ import annotations

import abc
import inspect
from dataclasses import dataclass, field
from typing import Callable, ClassVar, Sequence

import numpy as np
import torch

from zodrive.attacks.objectives import Objective
from zodrive.attacks.oracle import QueryOracle
from zodrive.attacks.schema import AttackOptions
from zodrive.attacks.threat import ThreatModel, distortion
from zodrive.errors import ZodriveError

DEFAULTS = AttackOptions()
"""The schema's defaults, which an attack built directly (not from an `AttackSpec`) shares."""

ENGINE_VERSION = 2
"""Bumped whenever the driver's behaviour changes what an attack returns (results on disk
made by another version are not mixed with new ones). 2: one driver loop, per-row budgets,
the clean query reused, the best of every queried point. (One random stream per row left
every one-row result as it was: a one-row step draws what it drew before.)"""


@dataclass
class AttackResult:
    """What one attacked environment step produced, per environment row."""

    x_adv: np.ndarray            # (N, *obs) the observation the policy will receive
    success: np.ndarray          # (N,) goal met on x_adv
    already: np.ndarray          # (N,) goal already met on the clean observation
    iterations: np.ndarray       # (N,) iterations run
    queries: np.ndarray          # (N,) victim queries spent on this row (the oracle's count)
    linf: np.ndarray             # (N,) ||x_adv - x0||_inf
    l2: np.ndarray               # (N,) ||x_adv - x0||_2
    adv_outputs: np.ndarray      # (N, k) victim outputs on x_adv (seen by the attacker)
    clean_outputs: np.ndarray    # (N, k) victim outputs on x0
    trace: list[dict[str, np.ndarray]] = field(default_factory=list)  # per iteration: l1, l2 of the base point


class Best:
    """Tracks, per row, the best queried point: successful beats unsuccessful, then lower f."""

    def __init__(self, x: np.ndarray, out: np.ndarray, f: np.ndarray, ok: np.ndarray) -> None:
        self.x, self.out, self.f, self.ok = x.copy(), out.copy(), f.copy(), ok.copy()

    def offer(self, rows: np.ndarray, x: np.ndarray, out: np.ndarray, f: np.ndarray, ok: np.ndarray) -> None:
        better = (ok & ~self.ok[rows]) | ((ok == self.ok[rows]) & (f < self.f[rows]))
        take = rows[better]
        self.x[take], self.out[take] = x[better], out[better]
        self.f[take], self.ok[take] = f[better], ok[better]


class Attack(abc.ABC):
    """Base class: validated hyperparameters, a seeded generator, the driver `perturb`."""

    name: ClassVar[str]
    black_box: ClassVar[bool] = True
    search: ClassVar[bool] = True  # runs the driver below (T iterations of q proposals); False: its own perturb
    queries_clean: ClassVar[bool] = True  # asks the victim about the clean observation (so a base rate is known)
    no_search: ClassVar[str] = ""  # an attack that is no search (`search = False`): why the search options do nothing
    unread: ClassVar[tuple[str, ...]] = ()  # `AttackSpec` objective options it never reads (giving one is an error)
    reference: ClassVar[str] = ""

    def __init__(
        self,
        threat: ThreatModel,
        *,
        steps: int = DEFAULTS.steps,
        n_directions: int = DEFAULTS.n_directions,
        mu: float = DEFAULTS.mu,
        step_size: float = DEFAULTS.step_size,
        l2_weight: float = DEFAULTS.l2_weight,
        early_stop: bool = DEFAULTS.early_stop,
        patience: int | None = DEFAULTS.patience,
        warm_start: bool = DEFAULTS.warm_start,
        max_change: float | None = DEFAULTS.max_change,
        seed: int = DEFAULTS.seed,
    ) -> None:
        """Types and ranges are the schema's (`zodrive.attacks.schema`), checked where an
        `AttackSpec` is made; here only what needs the threat model."""
        if max_change is not None and threat.norm != "linf":
            raise ZodriveError("max_change bounds the L-inf change of the perturbation between steps: use norm linf")
        self.threat = threat
        self.steps = int(steps)
        self.n_directions = int(n_directions)
        self.mu = float(mu)
        self.step_size = float(step_size)
        self.l2_weight = float(l2_weight)
        self.early_stop = bool(early_stop)
        self.patience = None if patience is None else int(patience)
        self.warm_start = bool(warm_start)
        self.max_change = None if max_change is None else float(max_change)
        self.seed = seed
        self._rngs = [np.random.default_rng(seed)]  # one random stream per row
        # per row, the last step's best perturbation (warm start) and fed perturbation
        # (max_change); a row of NaN has none (its episode has just begun)
        self._carry: np.ndarray | None = None
        self._fed: np.ndarray | None = None

    def refuse_search_options(self, reads: tuple[str, ...] = ()) -> None:
        """An attack that is no search (its own `perturb`) reads none of the search options but
        `reads`: one given anyway would be ignored, which is an error."""
        for option, default in SEARCH_DEFAULTS.items():
            if option not in reads and getattr(self, option) != default:
                raise ZodriveError(f"attack {self.name}: {option} has no effect ({self.no_search})")

    @classmethod
    def check_objective(cls, objective: Objective) -> None:
        """An attack that never asks about the clean observation cannot judge a goal defined by it."""
        if not cls.queries_clean and objective.reads_clean:
            raise ZodriveError(needs_fixed_target(cls.name))

    def reseed(self, seed: int | Sequence[int]) -> None:
        """Restart the random streams (per episode, for reproducible episodes): one seed for
        a one-row attack, or one per row when rows are episodes run in lockstep."""
        seeds = [seed] if isinstance(seed, (int, np.integer)) else list(seed)
        self._rngs = [np.random.default_rng(s) for s in seeds]
        self.begin_episode()

    def begin_episode(self) -> None:
        """Forget the previous step's perturbation: a new episode starts from scratch."""
        self._carry = self._fed = None

    def restart_row(self, row: int, seed: int) -> None:
        """Row `row` begins a new episode (lockstep): a fresh stream, nothing carried."""
        self._rngs[row] = np.random.default_rng(seed)
        for state in (self._carry, self._fed):
            if state is not None:
                state[row] = np.nan

    def keep_rows(self, rows: np.ndarray) -> None:
        """Only `rows` go on (lockstep episodes that ended without a successor are dropped)."""
        self._rngs = [self._rngs[r] for r in rows]
        self._carry = None if self._carry is None else self._carry[rows]
        self._fed = None if self._fed is None else self._fed[rows]

    def draw(self, rows: np.ndarray, sample: Callable[[np.random.Generator], np.ndarray]) -> np.ndarray:
        """`sample` from each of `rows`' own streams, stacked: a row's random numbers do not
        depend on which other rows share the step, so N episodes in lockstep draw exactly
        what N one-row runs draw."""
        return np.stack([sample(self._rngs[r]) for r in rows])

    def normals(self, rows: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
        """Standard normals (len(rows), *shape), float64, each row's from its own stream: what
        `draw` with `standard_normal(shape)` returns, written in place (no per-row arrays)."""
        out = np.empty((len(rows), *shape))
        for i, r in enumerate(rows):
            self._rngs[r].standard_normal(out=out[i])
        return out

    def _streams(self, n: int) -> None:
        """One stream per row for a step of `n` rows; a caller that never seeded rows (a
        batch of states) gets row 0's stream from the attack's seed, row r's from (seed, r)."""
        if len(self._rngs) != n:
            self._rngs = [np.random.default_rng(self.seed if r == 0 else (self.seed, r)) for r in range(n)]

    # -- what an attack defines ---------------------------------------------------------
    @abc.abstractmethod
    def queries_per_run(self, steps: int | None = None) -> int:
        """Upper bound on victim queries of one run of `steps` (default T) iterations (the
        docstring's formula)."""

    def queries_per_step(self) -> int:
        """Upper bound on victim queries per environment step."""
        return self.queries_per_run()

    def first_iteration_cost(self) -> int:
        """Queries of the clean observation and one iteration (and, with `max_change`, of
        the admissible point nearest the clean one): the least a step can cost."""
        return self.queries_per_run(1) + (self.max_change is not None)

    def smooth_box(self, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """With `max_change`, the box (flattened, (N, dim) each) every fed point of this step
        must lie in: within max_change (L-inf) of the previous step's perturbation carried to
        the new clean observations `x0` (N, *obs) and re-projected into the threat model, so
        the box meets it; and which rows have one (N,). A row whose episode has just begun
        has none (an unbounded box). None when no row has one, or without `max_change`."""
        flat0 = x0.reshape(len(x0), -1)
        if self.max_change is None or self._fed is None or self._fed.shape != flat0.shape:
            return None
        has = ~np.isnan(self._fed).any(axis=1)
        if not has.any():
            return None
        fed = np.where(has[:, None], self._fed, 0.0).astype(self._fed.dtype)
        center = self.threat.project((flat0 + fed).reshape(x0.shape), x0).reshape(flat0.shape)
        low = np.where(has[:, None], center - self.max_change, -np.inf)
        high = np.where(has[:, None], center + self.max_change, np.inf)
        return low, high, has

    def init(self, x0: np.ndarray, mask: np.ndarray) -> np.ndarray:
        """The first base point of every row (N, dim) from the flattened clean x0 (N, dim)."""
        return x0.copy()

    def propose(self, k: int, x: np.ndarray, rows: np.ndarray, mask: np.ndarray) -> np.ndarray:
        """Points (A, P, dim) to query around the base points x (A, dim) of `rows`."""
        return np.empty((len(x), 0, x.shape[1]), dtype=np.float32)

    def keep_proposals(self, keep: np.ndarray) -> None:
        """Only the proposals of rows `keep` (A,) bool go on to `step` (a row whose budget
        cannot pay for its points stops): drop what `propose` kept for the others."""

    @abc.abstractmethod
    def step(self, k: int, cand: np.ndarray, f: np.ndarray, rows: np.ndarray, grad: np.ndarray | None) -> np.ndarray:
        """The next base points (A, dim) from the queried candidates (A, 1 + P, dim) (base
        point first), their objective values f (A, 1 + P) and, for white-box attacks, the
        gradient of L1 at the base point (A, dim)."""

    # -- the driver ---------------------------------------------------------------------
    def perturb(
        self, x0: np.ndarray, oracle: QueryOracle, objective: Objective, *, trace: bool = False
    ) -> AttackResult:
        """Attack clean observations `x0` (N, *obs); see the module docstring and `AttackResult`."""
        n, shape = len(x0), x0.shape[1:]
        dim = int(np.prod(shape))
        mask = self.threat.mask(shape).reshape(-1)
        flat0 = np.asarray(x0, dtype=np.float32).reshape(n, dim)
        oracle.begin_step(rows=n)
        box = self.smooth_box(flat0.reshape(n, *shape))

        around = self.threat.around(flat0, shape)

        def project(cand: np.ndarray, rows: np.ndarray) -> np.ndarray:  # (A, M, dim) into the threat model
            if cand.shape[1] == 0 or len(rows) == 0:  # an attack without probes (PGD, noise)
                return cand
            inside = around(cand, rows)
            if box is not None:  # both are boxes containing the carried point: clipping stays in both
                inside = np.clip(inside, box[0][rows, None], box[1][rows, None])
                # a point already inside up to rounding keeps its exact value (projection is then
                # idempotent, so a step onto a queried point is recognised and not queried again)
                snap = (np.abs(inside - cand) <= 1e-6) & box[2][rows, None, None]
                inside = np.where(snap, cand, inside)
            return inside

        def values(cand: np.ndarray, out: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, ...]:
            out_t, clean_t = torch.from_numpy(out), torch.from_numpy(clean[rows])
            l1 = objective.loss(out_t, clean_t).numpy().astype(np.float64)
            if self.l2_weight == 0 and not trace:  # f = l1 + 0 * l2 = l1 exactly: l2 is not needed
                return l1, None, l1, objective.success(out_t, clean_t).numpy()
            l2 = ((cand - flat0[rows, None]).astype(np.float64) ** 2).sum(axis=-1)
            return l1, l2, l1 + self.l2_weight * l2, objective.success(out_t, clean_t).numpy()

        def white_box_loss(rows: np.ndarray):  # L1 at the base points of `rows`, for autograd
            clean_t = None if rows is None else torch.from_numpy(clean[rows])
            return lambda out: objective.loss(out[:, None], out.detach() if clean_t is None else clean_t)[:, 0]

        everyone = np.arange(n)
        free = int(np.argmax(mask))  # a coordinate the attacker may change (any, if none)
        self._streams(n)
        if self.black_box:
            clean, grad0 = oracle(flat0.reshape(-1, *shape), everyone), None
        else:
            clean, grad0 = oracle.gradient(flat0.reshape(-1, *shape), white_box_loss(None), everyone)
        clean = clean.astype(np.float32)
        already = objective.already(torch.from_numpy(clean)).numpy()
        # the fallback: the clean observation, or with max_change the admissible point nearest it
        start, start_out, start_grad = flat0, clean, grad0
        if box is not None:
            start = project(flat0[:, None], everyone)[:, 0]
            moved = np.flatnonzero(np.any(start != flat0, axis=1))
            start_out = clean.copy()
            if moved.size and self.black_box:
                start_out[moved] = oracle(start[moved].reshape(-1, *shape), moved)
            elif moved.size:
                start_grad = grad0.copy()
                start_out[moved], start_grad[moved] = oracle.gradient(
                    start[moved].reshape(-1, *shape), white_box_loss(moved), moved)
        _, _, f0, ok0 = values(start[:, None], start_out[:, None], everyone)
        best = Best(start, start_out, f0[:, 0], already if box is None else ok0[:, 0])
        # the last evaluated base point of each row, so that it is never queried twice
        known_x, known_out = start.copy(), start_out.copy()
        known_grad = None if start_grad is None else start_grad.reshape(n, dim).astype(np.float32)

        iterations = np.zeros(n, dtype=np.int64)
        records: list[dict[str, np.ndarray]] = []
        x = self.init(flat0.copy(), mask).astype(np.float32)
        if self.warm_start and self._carry is not None and self._carry.shape == flat0.shape:
            # consecutive observations differ little: start where the last step ended
            carried = ~np.isnan(self._carry).any(axis=1)
            x = np.where(carried[:, None], flat0 + self._carry, x)
        x = project(x[:, None], everyone)[:, 0]
        active = ~best.ok if self.early_stop else np.ones(n, dtype=bool)
        active &= oracle.remaining(everyone) > 0
        stalled = np.zeros(n, dtype=np.int64)
        for k in range(self.steps):
            rows = np.flatnonzero(active)
            if rows.size == 0:
                break
            probes = project(self.propose(k, x[rows], rows, mask).astype(np.float32, copy=False), rows)
            cand = np.concatenate([x[rows, None], probes], axis=1)  # the base point is already projected
            need = np.ones(cand.shape[:2], dtype=bool)
            need[:, 0] = ~np.all(cand[:, 0] == known_x[rows], axis=1)
            afford = oracle.remaining(rows) >= need.sum(axis=1)
            if not afford.all():  # a row's own budget is spent: that row stops, the others go on
                active[rows[~afford]] = False
                rows, cand, need = rows[afford], cand[afford], need[afford]
                self.keep_proposals(afford)
                if rows.size == 0:
                    break
            a, m = cand.shape[:2]
            owners = np.repeat(rows, need.sum(axis=1))
            grad = None
            if self.black_box and owners.size == a * m:  # every point is new (the usual case): one call
                out = oracle(cand.reshape(-1, *shape), owners).reshape(a, m, -1).astype(np.float32, copy=False)
            else:  # a known base point is not asked again: its outputs are filled in
                out = np.empty((a, m, clean.shape[1]), dtype=np.float32)
                out[~need[:, 0], 0] = known_out[rows[~need[:, 0]]]
                if self.black_box and owners.size:
                    out[need] = oracle(cand[need].reshape(-1, *shape), owners)
                elif not self.black_box:
                    grad = known_grad[rows].copy()
                    ask = need[:, 0]
                    if ask.any():
                        o, g = oracle.gradient(cand[ask, 0].reshape(-1, *shape), white_box_loss(rows[ask]),
                                               rows[ask])
                        out[ask, 0], grad[ask] = o, g.reshape(-1, dim)
                    known_grad[rows] = grad
            known_x[rows], known_out[rows] = cand[:, 0], out[:, 0]
            iterations[rows] += 1
            l1, l2, f, ok = values(cand, out, rows)
            has_ok = ok.any(axis=1)
            pick = np.where(has_ok, np.where(ok, f, np.inf).argmin(axis=1), f.argmin(axis=1))
            ar = np.arange(a)
            if self.patience is None:
                best.offer(rows, cand[ar, pick], out[ar, pick], f[ar, pick], ok[ar, pick])
            else:  # give up on a step that has stopped improving
                before_f, before_ok = best.f[rows].copy(), best.ok[rows].copy()
                best.offer(rows, cand[ar, pick], out[ar, pick], f[ar, pick], ok[ar, pick])
                improved = (best.f[rows] < before_f) | (best.ok[rows] & ~before_ok)
                stalled[rows] = np.where(improved, 0, stalled[rows] + 1)
                active[rows[stalled[rows] >= self.patience]] = False
            if trace:
                rec = {"l1": np.full(n, np.nan), "l2": np.full(n, np.nan)}
                rec["l1"][rows], rec["l2"][rows] = l1[:, 0], l2[:, 0]
                records.append(rec)
            if self.early_stop:
                active[rows[has_ok]] = False
            if k == self.steps - 1:
                break
            x[rows] = project(self.step(k, cand, f, rows, grad)[:, None].astype(np.float32), rows)[:, 0]
            if self.black_box:  # a step onto a queried point (random search) costs no new query
                same = cand[:, :, free] == x[rows, None, free]  # one coordinate first: most points differ there
                if same.any():
                    same &= np.all(cand == x[rows, None], axis=2)
                hit = same.any(axis=1)
                col = same.argmax(axis=1)[hit]
                known_x[rows[hit]], known_out[rows[hit]] = cand[hit, col], out[hit, col]
        if self.warm_start:
            self._carry = best.x - flat0
        fed, fed_out = best.x, best.out
        if self.max_change is not None:
            self._fed = fed - flat0
        x_adv = fed.reshape(n, *shape).astype(x0.dtype)
        linf, l2n = distortion(x_adv, x0)
        return AttackResult(
            x_adv=x_adv, success=best.ok & ~already, already=already, iterations=iterations,
            queries=oracle.row_queries.copy(), linf=linf, l2=l2n,
            adv_outputs=fed_out, clean_outputs=clean, trace=records,
        )


def needs_fixed_target(name: str) -> str:
    """The error for an untargeted or worst-action goal given to an attack that never queries the
    clean observation (`Attack.queries_clean` False)."""
    return (f"attack {name} never queries the clean observation, so it cannot judge a goal defined by it: give it a "
            "fixed target (auto is the paper's; an action, or not:ACTION; not none or worst)")


ENGINE_OPTIONS = tuple(name for name, p in inspect.signature(Attack.__init__).parameters.items()
                       if p.kind is p.KEYWORD_ONLY)
"""The schema's options every attack takes (`AttackSpec` passes them to `make_attack`)."""
# the search options and their defaults (mu and step_size are read by the searches that use them
# only, so they are not checked)
SEARCH_DEFAULTS = {name: getattr(DEFAULTS, name) for name in ENGINE_OPTIONS if name not in ("mu", "step_size")}


class GradientEstimateAttack(Attack):
    """Attacks that estimate a gradient from finite differences around the base point.

    They differ only in the directions they draw and the step they take (as in foolbox/ART).
    Queries per environment step: at most T * (1 + q) with forward differences, T * (1 + 2q)
    with central ones (the clean query is iteration 0's base point).
    """

    antithetic: ClassVar[bool] = False  # central differences f(x+mu u) - f(x-mu u)
    unit_directions: ClassVar[bool] = False  # E[u u^T] = I/d: scale the estimate by d

    def queries_per_run(self, steps: int | None = None) -> int:
        return (steps or self.steps) * (1 + self.n_directions * (2 if self.antithetic else 1))

    @abc.abstractmethod
    def directions(self, rows: np.ndarray, dim: int, mask: np.ndarray) -> np.ndarray:
        """(len(rows), q, dim) directions for `rows` (each from its own stream, `draw`),
        zero on masked coordinates."""

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

    def init(self, x0: np.ndarray, mask: np.ndarray) -> np.ndarray:
        self._d_free = int(mask.sum())
        self.start(x0)
        return x0.copy()

    def start(self, x0: np.ndarray) -> None:
        """Per-call state (e.g. an optimizer) before the first update."""

    def propose(self, k: int, x: np.ndarray, rows: np.ndarray, mask: np.ndarray) -> np.ndarray:
        self._u = self.directions(rows, x.shape[1], mask).astype(np.float32)
        if not self.antithetic:
            return x[:, None] + self.mu * self._u
        return np.concatenate([x[:, None] + (s * self.mu) * self._u for s in (1.0, -1.0)], axis=1)

    def keep_proposals(self, keep: np.ndarray) -> None:
        self._u = self._u[keep]

    def step(self, k: int, cand: np.ndarray, f: np.ndarray, rows: np.ndarray, grad: np.ndarray | None) -> np.ndarray:
        return self.update(cand[:, 0], self.estimate(f, self._u, self._d_free), rows)

    @abc.abstractmethod
    def update(self, x: np.ndarray, g: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """One step from flattened iterates x (A, dim) with estimate g (A, dim)."""


def unit_sphere(normal: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Directions (..., dim) uniform on the unit sphere of the unmasked subspace, from
    standard normal draws of that shape (all rows normalized in one call; `normal`, float64,
    is overwritten)."""
    normal *= mask
    norm = np.sqrt(np.add.reduce(normal * normal, axis=-1, keepdims=True))  # np.linalg.norm's arithmetic
    normal /= np.maximum(norm, 1e-12)
    return normal
