"""Vertex hold: a decision-based attack at one query per step that keeps what works.

Decision-based access (the victim's answer only; Brendel, Rauber, Bethge, "Decision-Based
Adversarial Attacks", ICLR 2018) and one perturbation kept over many steps (CopyCAT: Hussenot,
Geist, Pietquin, "Taking Control of Neural Policies with Constant Attacks", AAMAS 2020) come
from the literature; the rule is zodrive's. Each step, per environment row:

    feed the vertex held from the last step if there is one, else a random vertex (+-eps on
    every free coordinate) of the L-inf ball, projected into the threat model (the box may clip it);
    query the victim once on what was fed (what a real attacker sees as the car's next move);
    hold that perturbation for the next step if the victim took the target action, else drop it.

Why it exists: on some victims the target action is reachable from many vertices of the ball,
and a vertex that works at one step still works at the next (models/dqn-close at eps 0.02:
38-44 % of random vertices, 95 % still working a step later; `results/learned-adversary`).
There a search (tens of queries per step) is not needed; where the target is rarely reachable
this way (the DQN driver at eps 0.02) this attack does nearly nothing. The clean observation
is never queried, so no base rate is known: its success is the share of steps on which the
victim took the target under attack.

`vertex-hold:DIR` picks the fresh vertex instead of drawing it blind: of `candidates` random vertices,
the one a picker fitted offline from counted queries (`zodrive picker-train`,
`zodrive.attacks.picker`) rates most likely to make the victim take the target; a held vertex the
picker rates below its `switch` at the new state is replaced the same way. The picker runs locally.

`vertex-check:DIR` (`VertexCheck`, below) spends the query before feeding instead: the vertex about to be
fed is checked, and one that would fail is swapped for the picker's best fresh vertex, fed unasked.

Queries per environment step: 1 (with a picker too; `vertex-check:DIR --check-below` averages at most 1).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from zodrive.attacks.base import Attack, AttackResult
from zodrive.attacks.objectives import Objective
from zodrive.attacks.oracle import QueryOracle
from zodrive.attacks.picker import Picker, check_picker, digest, objective_target
from zodrive.attacks.threat import ThreatModel, distortion
from zodrive.errors import ZodriveError


class VertexHold(Attack):
    name = "vertex-hold"
    search = False
    queries_clean = False
    no_search = "vertex hold queries one point per step and only asks whether the victim took the target"
    reads = frozenset({"seed", "target", "tol"})  # (`tol`: a continuous target's tolerance)
    reference = ("zodrive's rule over decision-based access (Brendel et al., ICLR 2018) and constant "
                 "perturbations over time (CopyCAT, Hussenot et al., AAMAS 2020)")
    on_decisions = True  # it reads only whether the victim took the target
    trained = "picker"  # optional for vertex hold (without one it draws vertices blind)

    @classmethod
    def check_folder(cls, folder: str | None, *, model_file: str, preset: dict[str, Any], defense: str | None,
                     defense_version: int | None = None) -> None:
        if folder is not None:
            check_picker(folder, model_file=model_file, preset=preset, defense=defense)

    @classmethod
    def folder_digest(cls, folder: str) -> str:
        return digest(folder)

    def __init__(self, threat: ThreatModel, *, adversary: str | None = None, **kwargs: Any) -> None:
        """`adversary`: a picker's folder (`vertex-hold:DIR`), else vertices are drawn blind."""
        super().__init__(threat, **kwargs)
        if threat.norm != "linf":
            raise ZodriveError("attack vertex-hold draws vertices of the L-inf ball: use norm linf")
        self.picker: Picker | None = None
        self.picker_goal: Any = None
        self.picker_frozen: list[str] | None = None
        self._checked: Objective | None = None  # the objective the picker was last checked against
        if adversary is not None:
            picker, meta = Picker.load(adversary)
            self.use_picker(picker, {"target": meta["target"], "tol": meta["tol"]})
            if float(meta["eps"]) != threat.eps:
                raise ZodriveError(f"picker {adversary} was fitted for eps {meta['eps']:g}, not {threat.eps:g}")
            self.picker_frozen = sorted(meta["frozen"])  # checked by `check_objective`, once the mask is the real one

    def queries_per_run(self, steps: int | None = None) -> int:
        return 1

    def first_iteration_cost(self) -> int:
        return 1

    def use_picker(self, picker: Picker, goal: dict[str, Any]) -> None:
        """Pick fresh vertices with `picker`, fitted for `goal` (`objective_target`); also used while one is fitted."""
        self.picker, self.picker_goal, self._checked = picker, goal, None

    # an instance method over the base's classmethod: the base's check needs only the class, this
    # one also reads the picker an instance holds (every caller has the instance)
    def check_objective(self, objective: Objective) -> None:  # type: ignore[override]
        """Also, with a picker: the goal and the frozen features it was fitted for (`AttackSpec.build`
        calls this with the victim's objective and the real threat model; `AttackSpec.check` knows neither)."""
        super().check_objective(objective)
        if self.picker is None or objective is self._checked:  # `perturb` checks every step: once is enough
            return
        if self.picker_frozen is not None and self.picker_frozen != sorted(self.threat.frozen):
            raise ZodriveError(f"the picker was fitted with {self.picker_frozen} frozen, "
                               f"not {sorted(self.threat.frozen)}")
        if objective_target(objective) != self.picker_goal:
            raise ZodriveError(f"the picker ranks vertices for {self.picker_goal}, not "
                               f"{objective_target(objective)}: fit one for this target")
        self._checked = objective

    def step(self, k: int, cand: np.ndarray, f: np.ndarray, rows: np.ndarray, grad: np.ndarray | None) -> np.ndarray:
        raise AssertionError("vertex hold takes no search step")  # perturb is its own

    def perturb(self, x0: np.ndarray, oracle: QueryOracle, objective: Objective, *, trace: bool = False
                ) -> AttackResult:
        """The step above for clean observations `x0` (N, *obs)."""
        x0, delta, _ = self._begin(x0, oracle, objective)
        fed = self._project(x0, delta)
        out, took = self.ask(fed, np.ones(len(x0), dtype=bool), oracle, objective)
        # the vertex itself is held, not its projection: a coordinate the box clipped at this step
        # is whole again at the next one if the observation has moved away from the edge
        self._carry = np.where(took[:, None], delta, np.nan).astype(np.float32)
        return self._result(x0, fed, took, out, oracle)

    def _begin(self, x0: np.ndarray, oracle: QueryOracle, objective: Objective
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Start a step: clean observations as float32, each row's flat vertex to try (held, or fresh
        where none is held or the picker's `switch` drops it), and the picker's rating of each row's
        vertex where it is the held one and `_rates_held`, else -inf."""
        self.check_objective(objective)
        n, shape = len(x0), tuple(x0.shape[1:])
        dim = int(np.prod(shape))
        x0 = np.asarray(x0, dtype=np.float32)
        flat0 = x0.reshape(n, dim)
        oracle.begin_step(rows=n)
        self._streams(n)
        held = self._carry if self._carry is not None and self._carry.shape == flat0.shape else \
            np.full((n, dim), np.nan, dtype=np.float32)
        delta = np.where(np.isnan(held), 0.0, held).astype(np.float32)
        stale = np.isnan(held).any(axis=1)
        rating = np.full(n, -np.inf)  # the picker's rating of each held vertex at this step
        if self._rates_held():
            assert self.picker is not None  # only a picker rates
            for r in np.flatnonzero(~stale):  # one call per row: lockstep = one-row runs
                rating[r] = self.picker.scores(self._project(x0[r:r + 1], delta[r:r + 1]))[0]
            stale |= rating < self.picker.switch  # a held vertex rated below `switch` here may be replaced
        fresh = np.flatnonzero(stale)
        if fresh.size:
            drawn, rated = self.fresh(flat0[fresh], fresh, shape)
            take = rated >= rating[fresh]  # a held vertex stays unless a candidate rates higher
            delta[fresh[take]] = drawn[take]
            rating[fresh[take]] = -np.inf
        return x0, delta, rating

    def _rates_held(self) -> bool:
        """Whether a step needs the picker's rating of the held vertex (for `switch`)."""
        return self.picker is not None and self.picker.switch > 0

    def _project(self, x0: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """The observations fed for flat vertices `delta`, projected once into the threat model (the
        L-inf projection is elementwise: row by row is the same)."""
        return self.threat.project((x0.reshape(len(x0), -1) + delta).reshape(x0.shape), x0).astype(np.float32)

    def ask(self, fed: np.ndarray, mask: np.ndarray, oracle: QueryOracle, objective: Objective
             ) -> tuple[np.ndarray, np.ndarray]:
        """One counted query per row in `mask` on `fed`: the outputs (NaN for a row not asked) and
        whether the victim took the target. Public, as `fresh` is, so that a study can replace how a
        step asks or draws (studies/learned-adversary/pilots/one-query/hard.py)."""
        asked = np.flatnonzero(mask)
        took = np.zeros(len(fed), dtype=bool)
        if not asked.size:  # vertex check skipped every check: no outputs, as on a step with nothing asked
            return np.full((len(fed), 0), np.nan, dtype=np.float32), took
        answered, took[asked] = self._query(fed[asked], asked, oracle, objective)
        out = np.full((len(fed), answered.shape[1]), np.nan, dtype=np.float32)
        out[asked] = answered
        return out, took

    def _query(self, fed: np.ndarray, rows: np.ndarray, oracle: QueryOracle, objective: Objective
               ) -> tuple[np.ndarray, np.ndarray]:
        """The victim's outputs on `fed`, one counted query charged to each of `rows`, and whether it took
        the target."""
        answered = np.asarray(oracle(fed, rows), dtype=np.float32)
        out_t = torch.from_numpy(answered)
        # targeted: the clean output is not read
        return answered, objective.success(out_t[:, None], out_t)[:, 0].numpy()

    def _result(self, x0: np.ndarray, fed: np.ndarray, success: np.ndarray, out: np.ndarray,
                oracle: QueryOracle) -> AttackResult:
        n = len(x0)
        linf, l2 = distortion(fed, x0)
        return AttackResult(x_adv=fed, success=success, already=np.zeros(n, dtype=bool),  # clean never asked
                            iterations=np.ones(n, dtype=np.int64), queries=oracle.row_queries.copy(), linf=linf, l2=l2,
                            adv_outputs=out, clean_outputs=np.full_like(out, np.nan))

    def fresh(self, flat0: np.ndarray, rows: np.ndarray, shape: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
        """A new vertex (unprojected, flat) for each of `rows` (clean observations `flat0`) and its rating:
        a random one (rated +inf), or with a picker the best-rated of `candidates` random ones at the
        row's observation (one picker call per row)."""
        if self.picker is None:
            signs = np.array([-self.threat.eps, self.threat.eps], dtype=np.float32)
            mask = self.threat.mask(shape).reshape(-1)
            return self.draw(rows, lambda g: g.choice(signs, size=flat0.shape[1])) * mask, np.full(len(rows), np.inf)
        drawn, scores = self._rated(flat0, rows, shape)
        best = scores.argmax(axis=1)
        return drawn[np.arange(len(rows)), best], scores.max(axis=1).astype(np.float64)

    def _rated(self, flat0: np.ndarray, rows: np.ndarray, shape: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
        """`candidates` random vertices (rows, k, dim) for each of `rows` and the picker's ratings (rows, k)
        of them at the row's observation (one picker call per row)."""
        assert self.picker is not None  # called with a picker only (`fresh`)
        eps = np.float32(self.threat.eps)
        mask = self.threat.mask(shape).reshape(-1)
        signs = np.array([-eps, eps], dtype=np.float32)
        k = self.picker.candidates
        drawn = self.draw(rows, lambda g: g.choice(signs, size=(k, flat0.shape[1]))) * mask  # (rows, k, dim)
        scores = np.empty((len(rows), k), dtype=np.float32)
        for i in range(len(rows)):
            base = np.repeat(flat0[i:i + 1], k, axis=0).reshape(-1, *shape)
            scores[i] = self.picker.scores(self.threat.project(base + drawn[i].reshape(-1, *shape), base))
        return drawn, scores


PLAIN_CHECK = ("vertex-check needs a picker: --attack vertex-check:DIR (`zodrive picker-train`); without one it was "
               "removed from zodrive (docs/attacks.md, section \"Removed options\")")


class VertexCheck(VertexHold):
    """Vertex hold with a picker that asks before it feeds: the one query of a step checks the vertex
    about to be fed (the one fed at the last step, or a fresh one); if the victim would not take the
    target on it, a fresh vertex is fed instead, unasked, and is the one checked at the next step.

    Vertex hold learns that a held vertex stopped working only from the victim's move on it; here
    the query comes first, so that move is never made on a vertex known to fail. A step is missed
    only when the check fails and the fresh vertex fails too. A vertex fed unasked has unknown
    outputs (NaN) and its step counts as no success: `success` is the share of steps on which a
    check confirmed the target (a lower bound on the share taken; the action counts give the rest).

    `check_below`: a held vertex the picker rates at least this at the new state is
    fed without a check, and each query so saved pays for one check of a fresh vertex where a check
    fails (the picker's best first, up to `candidates`). A row never spends more queries than steps
    so far in its episode, so the average stays at most one per step; one step may spend more.

    Queries per environment step: 1; with `check_below`, at most 1 + candidates in one step and at
    most 1 per step on average over every prefix of an episode."""

    name = "vertex-check"
    no_search = "vertex check queries one point per step and only asks whether the victim would take the target"

    def __init__(self, threat: ThreatModel, *, adversary: str | None = None, check_below: float | None = None,
                 **kwargs: Any) -> None:
        if adversary is None:
            raise ZodriveError(PLAIN_CHECK)
        super().__init__(threat, adversary=adversary, **kwargs)
        self.check_below = None if check_below is None else float(check_below)
        self._bank: np.ndarray | None = None  # per row: queries earned (one per step) and not yet spent

    def queries_per_run(self, steps: int | None = None) -> int:
        assert self.picker is not None  # vertex check always has one (`__init__`)
        return 1 if self.check_below is None else 1 + self.picker.candidates

    def _rates_held(self) -> bool:
        return super()._rates_held() or self.check_below is not None

    def begin_episode(self) -> None:
        super().begin_episode()
        self._bank = None

    def restart_row(self, row: int, seed: int) -> None:
        super().restart_row(row, seed)
        if self._bank is not None:
            self._bank[row] = 0

    def keep_rows(self, rows: np.ndarray) -> None:
        super().keep_rows(rows)
        self._bank = None if self._bank is None else self._bank[rows]

    def perturb(self, x0: np.ndarray, oracle: QueryOracle, objective: Objective, *, trace: bool = False
                ) -> AttackResult:
        x0, delta, rating = self._begin(x0, oracle, objective)
        n, shape = len(x0), tuple(x0.shape[1:])
        flat0 = x0.reshape(n, -1)
        if self._bank is None or len(self._bank) != n:
            self._bank = np.zeros(n, dtype=np.int64)
        self._bank += 1
        ask = np.ones(n, dtype=bool) if self.check_below is None else rating < self.check_below  # -inf: a fresh vertex
        fed = self._project(x0, delta)
        out, took = self.ask(fed, ask, oracle, objective)
        self._bank[ask] -= 1
        failed = np.flatnonzero(ask & ~took)
        if failed.size and self.check_below is None:
            delta[failed] = self.fresh(flat0[failed], failed, shape)[0]
        elif failed.size:
            drawn, scores = self._rated(flat0[failed], failed, shape)
            for i, r in enumerate(failed):
                for j in np.argsort(-scores[i], kind="stable"):  # the best-rated first
                    delta[r] = drawn[i, j]
                    if self._bank[r] < 1 or oracle.remaining(np.array([r]))[0] < 1:
                        break  # fed unasked
                    answer, ok = self._query(self._project(x0[r:r + 1], delta[r:r + 1]), np.array([r]), oracle,
                                             objective)
                    self._bank[r] -= 1
                    if ok[0]:
                        out[r], took[r] = answer[0], True
                        break
        out[failed[~took[failed]]] = np.nan  # fed unasked
        if failed.size:  # only their vertices changed (the projection is row by row)
            fed[failed] = self._project(x0[failed], delta[failed])
        self._carry = delta.astype(np.float32)
        return self._result(x0, fed, took, out, oracle)
