"""The attack interface and the one driver loop every attack runs in.

An attack turns clean observations `x0` (N environments at once) into perturbed ones
inside a `ThreatModel`, talking to the victim only through a `QueryOracle`. The driver
(`Attack.perturb`, its phases in `Search`) owns everything attacks share, so that no attack can
get it wrong:

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
(`propose`) and where to go next (`step`); a decision-based one (`attacks.boundary`) also reads
which candidates met the goal (`observe`) and ranks successful points itself (`merit`). The
objective is the paper's Eq. 8: L1 (from `objectives`) + l2_weight * ||x - x0||^2. White-box baselines (`black_box =
False`) get the exact gradient of L1 at the base point instead of probes. Two attacks are no
search and bring their own `perturb` (`search = False`): the learned adversary
(`attacks.learned`) and vertex hold (`attacks.hold`).
"""

from __future__ import annotations

import abc
import inspect
from dataclasses import dataclass, field
from typing import Any, Callable, ClassVar, Mapping, Sequence

import numpy as np
import torch

from zodrive.attacks.objectives import Objective
from zodrive.attacks.oracle import QueryOracle
from zodrive.attacks.schema import AttackOptions
from zodrive.attacks.threat import ThreatModel, distortion
from zodrive.errors import ZodriveError

DEFAULTS = AttackOptions()
"""The schema's defaults, which an attack built directly (not from an `AttackSpec`) shares."""
TUNABLE = ("steps", "n_directions", "mu", "step_size", "l2_weight", "early_stop", "patience", "warm_start",
           "max_change", "seed", "target", "loss", "weight", "kappa", "tol")
"""The schema's options that some attacks read and others do not (each attack says which, `Attack.reads`);
the others (the attack, the budget ball, the frozen features, the query budget) every attack reads."""


def reads_all_but(*unread: str) -> frozenset[str]:
    """The tunable options but `unread`: an attack's `reads`."""
    assert set(unread) <= set(TUNABLE), unread
    return frozenset(TUNABLE) - set(unread)

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
    attacked: np.ndarray | None = None  # (N,) whether the attack ran (a frequency budget skips steps); None: it did
    referee_queries: np.ndarray | None = None  # (N,) rows the harness sent to judge the step (`refereed`); None: none


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
    refereed: ClassVar[bool] = False
    """It makes no victim query and states no verdict (transfer): after each step the harness asks the victim
    about the clean and the fed observation (`QueryOracle.referee`, counted apart) to judge it."""
    no_search: ClassVar[str] = ""  # an attack that is no search (`search = False`): why the search options do nothing
    reads: ClassVar[frozenset[str]] = frozenset(TUNABLE)  # the tunable options it reads; another one given is an error
    reference: ClassVar[str] = ""
    on_decisions: ClassVar[bool] = False
    """Meaningful when each query returns only the decision (`access: decision`, one-hot outputs): it needs
    no score margin (it samples, or reads only whether the goal is met). Others are refused there
    (`spec.decision_refusal` says why)."""
    trained: ClassVar[str] = ""
    """What it reads from a trained folder (`NAME:DIR`, the spec's `adversary`), fitted against one model on one
    preset: "adversary" (learned), "picker" (vertex hold and vertex check), "surrogate" (transfer); "" for the
    attacks that read none. An evaluation refuses a folder fitted against another system (`check_folder`) and
    keys its results on the folder's content (`folder_digest`)."""
    goal: ClassVar[bool] = True
    """It aims at a per-step goal (a target, or a changed action), so a step can succeed; the learned adversary
    lowers the return over an episode and has none (no success rate, no base rate)."""

    @classmethod
    def check_folder(cls, folder: str | None, *, model_file: str, preset: dict[str, Any], defense: str | None,
                     defense_version: int | None = None) -> None:
        """Refuse the trained folder `folder` (None: none given) where it was fitted against another model file,
        preset or defense than this evaluation's (one line saying which); an attack that reads none has
        nothing to check."""

    @classmethod
    def folder_digest(cls, folder: str) -> str:
        """What an evaluation's key records of the trained folder `folder`: its content's SHA-256 (a refitted
        folder is another attack)."""
        raise ZodriveError(f"attack {cls.name} reads no trained folder")

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
        refuse_unread(type(self), {name: getattr(self, name) for name in ENGINE_OPTIONS})
        self._rngs = [np.random.default_rng(seed)]  # one random stream per row
        # per row, the last step's best perturbation (warm start) and fed perturbation
        # (max_change); a row of NaN has none (its episode has just begun)
        self._carry: np.ndarray | None = None
        self._fed: np.ndarray | None = None

    @property
    def carried(self) -> np.ndarray | None:
        """Per row, the perturbation carried to the next step (the warm start; vertex hold's held
        vertex), flat; a row of NaN carries none. Read-only: for studies and traces."""
        return self._carry

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

    def fed_clean(self, x0: np.ndarray) -> None:
        """The step of clean observations `x0` (N, *obs) was not attacked (a frequency budget skipped
        it): with max_change, the next fed perturbation drifts from none, the one the victim last saw."""
        if self.max_change is not None:
            self._fed = np.zeros((len(x0), int(np.prod(x0.shape[1:]))), dtype=np.float32)

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

    def observe(self, rows: np.ndarray, ok: np.ndarray) -> None:
        """Which queried candidates (A, 1 + P) of `rows` met the goal, told before `step` (a
        decision-based attack steps on this indicator alone); nothing by default."""

    def merit(self, f: np.ndarray, cand: np.ndarray, x0: np.ndarray, ok: np.ndarray) -> np.ndarray:
        """What ranks points (A, M, dim) of rows with clean points x0 (A, dim) for the best point
        (`Best`; successful points first, then lower merit): the objective f (A, M) by default."""
        return f

    @abc.abstractmethod
    def step(self, k: int, cand: np.ndarray, f: np.ndarray, rows: np.ndarray, grad: np.ndarray | None) -> np.ndarray:
        """The next base points (A, dim) from the queried candidates (A, 1 + P, dim) (base
        point first), their objective values f (A, 1 + P) and, for white-box attacks, the
        gradient of L1 at the base point (A, dim)."""

    # -- the driver ---------------------------------------------------------------------
    def perturb(
        self, x0: np.ndarray, oracle: QueryOracle, objective: Objective, *, trace: bool = False
    ) -> AttackResult:
        """Attack clean observations `x0` (N, *obs); see the module docstring and `AttackResult`.
        The phases are `Search`'s: the clean query, the fallback and the start point; then, per
        iteration, the candidates a row can pay for, their queries, the best point so far and who
        stops, and the step to the next base points; then the result."""
        search = Search(self, x0, oracle, objective, trace)
        search.query_clean()
        search.fallback()
        search.start_point()
        for k in range(self.steps):
            batch = search.candidates(k)
            if batch is None:  # every row has stopped
                break
            rows, cand, need = batch
            out, grad = search.ask(rows, cand, need)
            f = search.keep_best(rows, cand, out)
            if k == self.steps - 1:
                break
            search.advance(k, rows, cand, f, out, grad)
        return search.result(x0)


class Search:
    """One environment step of the driver (`Attack.perturb`) over N rows: the clean outputs, the
    best queried point of each row, the last point each row evaluated (never queried twice), the
    base points `x` and the rows still `active`."""

    def __init__(self, attack: Attack, x0: np.ndarray, oracle: QueryOracle, objective: Objective,
                 trace: bool) -> None:
        self.attack, self.oracle, self.objective, self.trace = attack, oracle, objective, trace
        self.n, self.shape = len(x0), x0.shape[1:]
        self.dim = int(np.prod(self.shape))
        self.mask = attack.threat.mask(self.shape).reshape(-1)
        self.flat0 = np.asarray(x0, dtype=np.float32).reshape(self.n, self.dim)
        self.integer = np.issubdtype(np.asarray(x0).dtype, np.integer)
        if self.integer and attack.max_change is not None:
            raise ZodriveError("max_change on integer observations (pixels) is not supported: rounding a point "
                               "toward the clean one may leave the max_change box")
        oracle.begin_step(rows=self.n)
        self.box = attack.smooth_box(self.flat0.reshape(self.n, *self.shape))
        self.around = attack.threat.around(self.flat0, self.shape, integer=self.integer)
        self.everyone = np.arange(self.n)
        self.free = int(np.argmax(self.mask))  # a coordinate the attacker may change (any, if none)
        self.iterations = np.zeros(self.n, dtype=np.int64)
        self.records: list[dict[str, np.ndarray]] = []
        self.ranks = type(attack).merit is not Attack.merit  # an attack that ranks points itself
        attack._streams(self.n)

    # -- the threat model and the objective -------------------------------------------
    def project(self, cand: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Points (A, M, dim) of `rows` into the threat model (and, with max_change, the box)."""
        if cand.shape[1] == 0 or len(rows) == 0:  # an attack without probes (PGD, noise)
            return cand
        inside = self.around(cand, rows)
        if self.box is not None:  # both are boxes containing the carried point: clipping stays in both
            low, high, has = self.box
            inside = np.clip(inside, low[rows, None], high[rows, None])
            # a point already inside up to rounding keeps its exact value (projection is then
            # idempotent, so a step onto a queried point is recognised and not queried again)
            snap = (np.abs(inside - cand) <= 1e-6) & has[rows, None, None]
            inside = np.where(snap, cand, inside)
        return inside

    def values(self, cand: np.ndarray, out: np.ndarray,
               rows: np.ndarray) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray]:
        """L1, L2 (None when not needed), f = L1 + l2_weight * L2 and success of points (A, M, dim)."""
        out_t, clean_t = torch.from_numpy(out), torch.from_numpy(self.clean[rows])
        l1 = self.objective.loss(out_t, clean_t).numpy().astype(np.float64)
        if self.attack.l2_weight == 0 and not self.trace:  # f = l1 + 0 * l2 = l1 exactly: l2 is not needed
            return l1, None, l1, self.objective.success(out_t, clean_t).numpy()
        l2 = ((cand - self.flat0[rows, None]).astype(np.float64) ** 2).sum(axis=-1)
        return l1, l2, l1 + self.attack.l2_weight * l2, self.objective.success(out_t, clean_t).numpy()

    def white_box_loss(self, rows: np.ndarray | None) -> Callable[[torch.Tensor], torch.Tensor]:
        """L1 at the base points of `rows` (None: at the clean points, judged against themselves), for autograd."""
        clean_t = None if rows is None else torch.from_numpy(self.clean[rows])
        return lambda out: self.objective.loss(out[:, None], out.detach() if clean_t is None else clean_t)[:, 0]

    # -- before the first iteration ------------------------------------------------------
    def query_clean(self) -> None:
        """Iteration 0's base point, asked once: the clean outputs (white-box: and the gradient)."""
        batch = self.flat0.reshape(-1, *self.shape)
        if self.attack.black_box:
            clean, self.grad0 = self.oracle(batch, self.everyone), None
        else:
            clean, self.grad0 = self.oracle.gradient(batch, self.white_box_loss(None), self.everyone)
        self.clean = clean.astype(np.float32)
        self.already = self.objective.already(torch.from_numpy(self.clean)).numpy()

    def fallback(self) -> None:
        """What a row is fed if nothing better is found, where its best point and its known point
        start: the clean observation, or with max_change the admissible point nearest it."""
        start, out, grad = self.flat0, self.clean, self.grad0
        if self.box is not None:
            start = self.project(self.flat0[:, None], self.everyone)[:, 0]
            moved = np.flatnonzero(np.any(start != self.flat0, axis=1))
            out = self.clean.copy()
            if moved.size and self.attack.black_box:
                out[moved] = self.oracle(start[moved].reshape(-1, *self.shape), moved)
            elif moved.size:
                assert self.grad0 is not None  # white-box: `query_clean` took the gradient
                grad = self.grad0.copy()
                out[moved], grad[moved] = self.oracle.gradient(
                    start[moved].reshape(-1, *self.shape), self.white_box_loss(moved), moved)
        _, _, f0, ok0 = self.values(start[:, None], out[:, None], self.everyone)
        ok0 = self.already[:, None] if self.box is None else ok0
        f0 = self.attack.merit(f0, start[:, None], self.flat0, ok0)
        self.best = Best(start, out, f0[:, 0], ok0[:, 0])
        self.known_x, self.known_out = start.copy(), out.copy()
        self.known_grad = None if grad is None else grad.reshape(self.n, self.dim).astype(np.float32)

    def start_point(self) -> None:
        """The first base points (the attack's `init`, or with warm start where the last step
        ended) and the rows that search: not yet won (early stop) and with budget left."""
        attack, carry = self.attack, self.attack._carry
        x = attack.init(self.flat0.copy(), self.mask).astype(np.float32)
        if attack.warm_start and carry is not None and carry.shape == self.flat0.shape:
            # consecutive observations differ little: start where the last step ended
            carried = ~np.isnan(carry).any(axis=1)
            x = np.where(carried[:, None], self.flat0 + carry, x)
        self.x = self.project(x[:, None], self.everyone)[:, 0]
        self.active = ~self.best.ok if attack.early_stop else np.ones(self.n, dtype=bool)
        self.active &= self.oracle.remaining(self.everyone) > 0
        self.stalled = np.zeros(self.n, dtype=np.int64)  # iterations without progress (patience)

    # -- one iteration -------------------------------------------------------------------
    def candidates(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The active rows that can pay for their points, the points (A, 1 + P, dim: the base point
        first) and which need a query (a known base point does not); None when no row is left."""
        rows = np.flatnonzero(self.active)
        if rows.size == 0:
            return None
        probes = self.project(self.attack.propose(k, self.x[rows], rows, self.mask).astype(np.float32, copy=False),
                              rows)
        cand = np.concatenate([self.x[rows, None], probes], axis=1)  # the base point is already projected
        need = np.ones(cand.shape[:2], dtype=bool)
        need[:, 0] = ~np.all(cand[:, 0] == self.known_x[rows], axis=1)
        afford = self.oracle.remaining(rows) >= need.sum(axis=1)
        if not afford.all():  # a row's own budget is spent: that row stops, the others go on
            self.active[rows[~afford]] = False
            rows, cand, need = rows[afford], cand[afford], need[afford]
            self.attack.keep_proposals(afford)
            if rows.size == 0:
                return None
        return rows, cand, need

    def ask(self, rows: np.ndarray, cand: np.ndarray, need: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """The victim's outputs on the candidates (A, 1 + P, k), in one call where every point is
        new, and for white-box attacks the gradient at the base points."""
        a, m = cand.shape[:2]
        owners = np.repeat(rows, need.sum(axis=1))
        grad = None
        if self.attack.black_box and owners.size == a * m:  # every point is new (the usual case): one call
            out = self.oracle(cand.reshape(-1, *self.shape), owners).reshape(a, m, -1).astype(np.float32, copy=False)
        else:  # a known base point is not asked again: its outputs are filled in
            out = np.empty((a, m, self.clean.shape[1]), dtype=np.float32)
            out[~need[:, 0], 0] = self.known_out[rows[~need[:, 0]]]
            if self.attack.black_box and owners.size:
                out[need] = self.oracle(cand[need].reshape(-1, *self.shape), owners)
            elif not self.attack.black_box:
                assert self.known_grad is not None  # white-box: `fallback` kept the gradient
                grad = self.known_grad[rows].copy()
                ask = need[:, 0]
                if ask.any():
                    o, g = self.oracle.gradient(cand[ask, 0].reshape(-1, *self.shape),
                                                self.white_box_loss(rows[ask]), rows[ask])
                    out[ask, 0], grad[ask] = o, g.reshape(-1, self.dim)
                self.known_grad[rows] = grad
        self.known_x[rows], self.known_out[rows] = cand[:, 0], out[:, 0]
        self.iterations[rows] += 1
        return out, grad

    def keep_best(self, rows: np.ndarray, cand: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Offer each row's best candidate (successful first, then the lowest f) to `best`; stop
        the rows that succeeded (early stop) or stopped improving (patience); return f (A, 1 + P)."""
        attack, best = self.attack, self.best
        l1, l2, f, ok = self.values(cand, out, rows)
        attack.observe(rows, ok)
        rank = attack.merit(f, cand, self.flat0[rows], ok) if self.ranks else f  # no copy of x0 per iteration
        has_ok = ok.any(axis=1)
        pick = np.where(has_ok, np.where(ok, rank, np.inf).argmin(axis=1), rank.argmin(axis=1))
        ar = np.arange(len(rows))
        before_f, before_ok = best.f[rows].copy(), best.ok[rows].copy()
        best.offer(rows, cand[ar, pick], out[ar, pick], rank[ar, pick], ok[ar, pick])
        if attack.patience is not None:  # give up on a step that has stopped improving
            improved = (best.f[rows] < before_f) | (best.ok[rows] & ~before_ok)
            self.stalled[rows] = np.where(improved, 0, self.stalled[rows] + 1)
            self.active[rows[self.stalled[rows] >= attack.patience]] = False
        if self.trace:
            assert l2 is not None  # `values` computes L2 for a trace
            rec = {"l1": np.full(self.n, np.nan), "l2": np.full(self.n, np.nan)}
            rec["l1"][rows], rec["l2"][rows] = l1[:, 0], l2[:, 0]
            self.records.append(rec)
        if attack.early_stop:
            self.active[rows[has_ok]] = False
        return f

    def advance(self, k: int, rows: np.ndarray, cand: np.ndarray, f: np.ndarray, out: np.ndarray,
                grad: np.ndarray | None) -> None:
        """The attack's step to the next base points, projected; a step onto a queried point
        (random search) takes that point's outputs, so it costs no new query."""
        step = self.attack.step(k, cand, f, rows, grad)[:, None].astype(np.float32)
        self.x[rows] = self.project(step, rows)[:, 0]
        if self.attack.black_box:
            x = self.x[rows, None]
            same = cand[:, :, self.free] == x[:, :, self.free]  # one coordinate first: most points differ there
            if same.any():
                same &= np.all(cand == x, axis=2)
            hit = same.any(axis=1)
            col = same.argmax(axis=1)[hit]
            self.known_x[rows[hit]], self.known_out[rows[hit]] = cand[hit, col], out[hit, col]

    # -- after the last iteration --------------------------------------------------------
    def result(self, x0: np.ndarray) -> AttackResult:
        """Each row is fed its best point; what carries to the next step is kept (warm start,
        max_change)."""
        attack, best = self.attack, self.best
        if attack.warm_start:
            attack._carry = best.x - self.flat0
        if attack.max_change is not None:
            attack._fed = best.x - self.flat0
        x_adv = best.x.reshape(self.n, *self.shape).astype(x0.dtype)
        linf, l2n = distortion(x_adv, x0)
        return AttackResult(
            x_adv=x_adv, success=best.ok & ~self.already, already=self.already, iterations=self.iterations,
            queries=self.oracle.row_queries.copy(), linf=linf, l2=l2n,
            adv_outputs=best.out, clean_outputs=self.clean, trace=self.records,
        )


def needs_fixed_target(name: str) -> str:
    """The error for an untargeted or worst-action goal given to an attack that never queries the
    clean observation (`Attack.queries_clean` False)."""
    return (f"attack {name} never queries the clean observation, so it cannot judge a goal defined by it: give it a "
            "fixed target (auto is the paper's; an action, or not:ACTION; not none or worst)")


ENGINE_OPTIONS = tuple(name for name, p in inspect.signature(Attack.__init__).parameters.items()
                       if p.kind is p.KEYWORD_ONLY)
"""The schema's options every attack takes (`AttackSpec` passes them to `make_attack`)."""


def refuse_unread(cls: type[Attack], values: Mapping[str, Any]) -> None:
    """The option rule: a tunable option (`TUNABLE`) that attack `cls` does not read (`Attack.reads`),
    given at a value other than the schema's default, would be ignored (and recorded as if it ran):
    an error."""
    for option in TUNABLE:
        if option in values and option not in cls.reads and values[option] != getattr(DEFAULTS, option):
            why = cls.no_search or f"{cls.name} reads only {', '.join(o for o in TUNABLE if o in cls.reads)}"
            raise ZodriveError(f"attack {cls.name}: {option} has no effect ({why})")


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
