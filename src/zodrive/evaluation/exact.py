"""Complete verification of a discrete ReLU MLP policy's decision, state by state (a MILP).

`certify` is sound, not complete: where CROWN cannot prove a margin, the state may still be
robust. Here each such state is decided over the same set (`threat_box`) by a mixed-integer
linear program (Tjeng et al., "Evaluating Robustness of Neural Networks with Mixed Integer
Programming", ICLR 2019), solved by HiGHS through `scipy.optimize.milp`:

- every hidden ReLU with CROWN pre-activation bounds l < 0 < u gets a binary (big-M encoding);
  a stable one (l >= 0 or u <= 0) is linear;
- for every action j that CROWN does not rule out, most threatening first, the MILP maximises
  score(j) - score(a*) over the box.

Verdicts, each one checked or kept on the safe side of a stated tolerance:

- "robust": for every j, HiGHS's bound on that maximum (its dual bound: valid even when it stops
  early) is below -(`SLACK` + `tolerance`): `SLACK` covers the float32 network's rounding (as
  in `certify`), `tolerance` HiGHS's own (1e-6 integrality, 1e-7 feasibility) carried to the
  scores by the weights. A state CROWN certifies is robust without a MILP.
- "attackable": a point of the box (clipped into it, rounded to float32) on which the real
  float32 network's argmax differs from a*, exactly the attacks' test of a changed action. A MILP
  optimum the float32 network does not confirm is re-solved once asking for a margin, then
  dropped.
- "unknown": the time limit ran out (`timed_out`), or the maximum lies between -(`SLACK` +
  `tolerance`) and what a float32 pass confirms: too close to call.

Before any MILP, a signed-gradient search (31 passes of 4 points through the float32 network)
looks for such a point: most attackable states end there. `time_limit` is a state's wall-clock
budget, checked before each MILP and handed to HiGHS as what is left; a MILP started on time
stops on time. White-box (reads the weights), no queries.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from scipy.optimize import Bounds, LinearConstraint, milp
from torch import nn

from zodrive.errors import ZodriveError
from zodrive.evaluation.certify import SLACK, box_of, crown_pre, margins, relu_scores

SOLVER_TOL = 1e-6  # HiGHS's default integrality tolerance; its feasibility tolerances (1e-7) are below it
WIDEN = 1e-9       # CROWN's float64 bounds are widened by this (relative and absolute) before the big-M
Affine = list[tuple[torch.Tensor, torch.Tensor]]


@dataclass(frozen=True)
class Exact:
    verdict: np.ndarray         # (N,) "robust" | "attackable" | "unknown"
    crown: np.ndarray           # (N,) bool: certified by CROWN (no MILP needed)
    timed_out: np.ndarray       # (N,) bool: unknown because the time limit ran out
    counterexample: np.ndarray  # (N, dim) float32 point that changes the action; NaN where none
    seconds: np.ndarray         # (N,) wall time spent on the state


def exact_network(net: nn.Module, kind: str) -> Affine:
    """The (W, b) layers of a discrete ReLU MLP policy; a ZodriveError for anything else."""
    if kind != "discrete":
        raise ZodriveError("--exact decides discrete policies (DQN, QR-DQN); a continuous actor is not supported")
    with torch.no_grad():
        affine = relu_scores(net)
    if affine is None:
        raise ZodriveError("--exact needs a ReLU MLP (Linear and ReLU layers only); this network has other "
                           "activations (use certify without --exact)")
    return [(w.detach(), b.detach()) for w, b in affine]


def exact(net: nn.Module, kind: str, x0: np.ndarray, eps: float | np.ndarray, mask: np.ndarray, low: float,
          high: float, *, time_limit: float = 10.0, crown_first: bool = True, falsify: bool = True,
          chunk: int = 64) -> Exact:
    """Exact verdicts for the clean states `x0` (N, ...) at radius `eps` (one number, or one per state:
    (N,)) (see the module docstring), with at most `time_limit` seconds per state. `crown_first=False`
    sends CROWN-certified states through the MILP too, `falsify=False` skips the gradient search that
    precedes it (both: checks)."""
    affine = exact_network(net, kind)
    radii = np.broadcast_to(np.asarray(eps, dtype=np.float64), (len(x0),))
    parts = []
    for start in range(0, len(x0), chunk):
        flat, lo, hi = box_of(x0[start:start + chunk], radii[start:start + chunk, None], mask, low, high)
        with torch.no_grad():
            action = net(flat.float()).argmax(dim=1)
            pre = crown_pre(affine, lo, hi)
            lower = margins(net, action, lo, hi, pre)
        for i in range(len(flat)):
            parts.append(_decide(net, affine, [(lb[i].numpy(), ub[i].numpy()) for lb, ub in pre], int(action[i]),
                                 lower[i].numpy(), lo[i].numpy(), hi[i].numpy(), time_limit, crown_first, falsify,
                                 flat[i].numpy()))
    return Exact(verdict=np.array([p[0] for p in parts], dtype=object), crown=np.array([p[1] for p in parts]),
                 timed_out=np.array([p[2] for p in parts]),
                 counterexample=np.stack([p[3] for p in parts]).astype(np.float32),
                 seconds=np.array([p[4] for p in parts]))


def _decide(net: nn.Module, affine: Affine, pre: list[tuple[np.ndarray, np.ndarray]], action: int,
            lower: np.ndarray, lo: np.ndarray, hi: np.ndarray, time_limit: float,
            crown_first: bool, falsify: bool, x0: np.ndarray) -> tuple[str, bool, bool, np.ndarray, float]:
    """One state: (verdict, CROWN-certified, timed out, counterexample or NaN, seconds)."""
    start = time.perf_counter()
    none = np.full(len(lo), np.nan)
    certified = bool(np.min(lower) > SLACK)
    if certified and crown_first:
        return "robust", True, False, none, time.perf_counter() - start
    if falsify:
        point = _falsify(net, lo, hi, action, x0)
        if point is not None:
            return "attackable", certified, False, point, time.perf_counter() - start
    program = _Program(affine, pre, lo, hi)
    w_last, b_last = (t.numpy() for t in affine[-1])
    undecided, timed_out = False, False
    others = [j for j in np.argsort(lower, kind="stable") if j != action and (not crown_first or lower[j] <= SLACK)]
    for j in others:
        c = w_last[j] - w_last[action]
        const = float(b_last[j] - b_last[action]) + float(c @ program.const)
        margin = SLACK + SOLVER_TOL * program.sensitivity(c, affine)
        left = time_limit - (time.perf_counter() - start)
        if left <= 0:
            timed_out = True
            break
        res = program.maximise(c, left)
        if res.x is not None:
            point = _into_box(res.x[:len(lo)], lo, hi)
            if _changes(net, point, action):
                return "attackable", certified, False, point, time.perf_counter() - start
        bound = _upper_bound(res, const)
        if bound is not None and bound < -margin:
            continue  # j cannot reach a*'s score anywhere in the box
        if res.status == 1:  # the time limit, before either side was proved
            timed_out = True
            break
        if res.x is not None and -float(res.fun) + const >= 0:  # an optimum float32 does not confirm: ask for a margin
            left = time_limit - (time.perf_counter() - start)
            if left > 0:
                again = program.maximise(c, left, at_least=margin - const)
                if again.x is not None:
                    point = _into_box(again.x[:len(lo)], lo, hi)
                    if _changes(net, point, action):
                        return "attackable", certified, False, point, time.perf_counter() - start
                timed_out = timed_out or again.status == 1
        undecided = True
    verdict = "unknown" if (undecided or timed_out) else "robust"
    return verdict, certified, timed_out, none, time.perf_counter() - start


def _upper_bound(res: Any, const: float) -> float | None:
    """What scipy's result proves about the maximum: HiGHS's dual bound (valid when it stopped
    early too), or a linear program's optimum (no unstable neuron: no binary, no dual bound).
    None when it proves nothing ("infeasible" over a box holding x0 is numerical trouble)."""
    if res.status in (0, 1) and res.mip_dual_bound is not None:
        return -float(res.mip_dual_bound) + const
    if res.status == 0 and res.fun is not None:
        return -float(res.fun) + const
    return None


def _falsify(net: nn.Module, lo: np.ndarray, hi: np.ndarray, action: int, x0: np.ndarray,
             steps: int = 30, starts: int = 4) -> np.ndarray | None:
    """A point of the box where the float32 network's argmax is not `action`, found by signed
    gradient ascent on the best other score minus a*'s (from x0 and random points), or None.
    Cheap, and settles most attackable states before any MILP; every point is checked."""
    generator = torch.Generator().manual_seed(0)
    low, high = torch.from_numpy(lo), torch.from_numpy(hi)
    x = torch.cat([torch.from_numpy(x0)[None], low + (high - low) * torch.rand(starts - 1, len(lo), generator=generator,
                                                                              dtype=torch.float64)])
    step = (high - low) / 8
    for _ in range(steps + 1):
        x = x.detach().requires_grad_(True)
        out = net(x.float())
        changed = torch.nonzero(out.argmax(dim=1) != action).flatten()
        for row in changed.tolist():
            point = _into_box(x[row].detach().numpy(), lo, hi)
            if _changes(net, point, action):
                return point
        others = out.clone()
        others[:, action] = -torch.inf
        gain = (others.max(dim=1).values - out[:, action]).sum()
        (grad,) = torch.autograd.grad(gain, x)
        x = torch.minimum(torch.maximum(x + step * grad.sign(), low), high)
    return None


def _into_box(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """x clipped into [lo, hi] and rounded to float32 without leaving it (lo, hi hold a float32 point)."""
    point = np.clip(x, lo, hi).astype(np.float32)
    wide = point.astype(np.float64)
    point = np.where(wide > hi, np.nextafter(point, np.float32(-np.inf)), point)
    point = np.where(wide < lo, np.nextafter(point, np.float32(np.inf)), point)
    return point.astype(np.float64)


def _changes(net: nn.Module, point: np.ndarray, action: int) -> bool:
    """True if the float32 network's argmax at `point` is not `action` (the attacks' test)."""
    with torch.no_grad():
        return int(net(torch.from_numpy(point.astype(np.float32))[None]).argmax(dim=1)[0]) != action


class _Program:
    """The network's graph over one box as MILP constraints. Variables: the input x, then the
    output h of each unstable ReLU, then its binary d; a stable neuron is no variable but an
    affine expression of those (always off: 0; always on: its pre-activation), which keeps the
    program as small as its unstable neurons."""

    def __init__(self, affine: Affine, pre: list[tuple[np.ndarray, np.ndarray]], lo: np.ndarray,
                 hi: np.ndarray) -> None:
        pre = [(lb - WIDEN * (1 + np.abs(lb)), ub + WIDEN * (1 + np.abs(ub))) for lb, ub in pre]
        unstable = [np.flatnonzero((lb < 0) & (ub > 0)) for lb, ub in pre]
        d, n_unstable = len(lo), sum(len(u) for u in unstable)
        self.n = d + 2 * n_unstable
        low, high = np.zeros(self.n), np.ones(self.n)
        low[:d], high[:d] = lo, hi
        expr, const = np.eye(d, self.n), np.zeros(d)        # the current layer's outputs, as affine expressions
        blocks, r_lo, r_hi = [], [], []
        h = d                                               # next unstable neuron's column; its binary: + n_unstable
        for k, (lb, ub) in enumerate(pre):
            w, b = (t.numpy() for t in affine[k])
            z, z0 = w @ expr, w @ const + b                  # pre-activations
            out, out0 = np.where((lb >= 0)[:, None], z, 0.0), np.where(lb >= 0, z0, 0.0)
            for n in unstable[k]:
                e_h, e_d = np.zeros(self.n), np.zeros(self.n)
                e_h[h], e_d[h + n_unstable] = 1.0, 1.0
                blocks += [e_h - z[n], e_h - z[n] - lb[n] * e_d, e_h - ub[n] * e_d]
                r_lo += [z0[n], -np.inf, -np.inf]           # h >= z;  h <= z - l (1 - d);  h <= u d
                r_hi += [np.inf, z0[n] - lb[n], 0.0]
                high[h] = ub[n]
                out[n], out0[n] = e_h, 0.0
                h += 1
            expr, const = out, out0
        self.expr, self.const = expr, const                 # the last hidden layer's outputs
        self.matrix = np.array(blocks).reshape(len(r_lo), self.n)
        self.row_lo, self.row_hi = np.array(r_lo), np.array(r_hi)
        self.bounds = Bounds(low, high)
        self.integrality = np.zeros(self.n)
        self.integrality[d + n_unstable:] = 1
        self.pre = pre

    def maximise(self, c: np.ndarray, seconds: float, at_least: float | None = None):
        """scipy's result for max c @ h_last - c @ (its constant part) over the graph (optionally with
        that objective >= at_least): add `c @ self.const` for c @ h_last."""
        objective = -(c @ self.expr)
        constraints = [LinearConstraint(self.matrix, self.row_lo, self.row_hi)] if len(self.row_lo) else []
        if at_least is not None:
            constraints.append(LinearConstraint(-objective[None], at_least, np.inf))
        return milp(objective, constraints=constraints, integrality=self.integrality, bounds=self.bounds,
                    options={"time_limit": max(seconds, 1e-3)})

    def sensitivity(self, c: np.ndarray, affine: Affine) -> float:
        """An upper bound on how far c @ h_last can move when every neuron and input is off by one
        unit times (1 + its magnitude): what the solver's tolerances can hide, carried by |W|."""
        g = np.abs(c)
        total = float(g.sum())
        for k in range(len(self.pre) - 1, -1, -1):
            lb, ub = self.pre[k]
            total += float(g @ (1 + np.maximum(np.abs(lb), np.abs(ub))))
            g = np.abs(affine[k][0].numpy()).T @ g
        x_size = np.maximum(np.abs(self.bounds.lb[:len(g)]), np.abs(self.bounds.ub[:len(g)]))
        return total + float(g @ (1 + x_size))


def exact_summary(net: nn.Module, kind: str, states: np.ndarray, eps: float, mask: np.ndarray,
                  bounds: tuple[float, float], time_limit: float, certified: np.ndarray,
                  won: np.ndarray | None) -> tuple[dict[str, Any], Exact]:
    """`exact` on `states` as certify.json's counts, and the verdicts themselves; `certified` (CROWN,
    from `certify`) and the states the attacks `won` are checked against the verdicts: each
    contradiction is counted (a sound, complete check has none)."""
    result = exact(net, kind, states, eps, mask, *bounds, time_limit=time_limit)
    robust, attackable = result.verdict == "robust", result.verdict == "attackable"
    summary: dict[str, Any] = {
        "time_limit": time_limit, "crown_certified": int(certified.sum()), "robust": int(robust.sum()),
        "attackable": int(attackable.sum()), "unknown": int((result.verdict == "unknown").sum()),
        "timed_out": int(result.timed_out.sum()), "seconds_median": float(np.median(result.seconds)),
        "seconds_max": float(np.max(result.seconds)),
        "contradictions": int((certified & ~robust).sum()) + (0 if won is None else int((won & robust).sum())),
    }
    summary.update({f"{key}_share": summary[key] / len(states) for key in ("robust", "attackable", "unknown")})
    return summary, result


def attack_gap(verdict: np.ndarray, won: np.ndarray) -> dict[str, Any]:
    """How far an attack is from optimal on states the exact check decided (`verdict` (N,) as
    `Exact.verdict`, `won` (N,) bool: the attack changed the action). `found` + `missed` =
    `attackable`; `found` + `won_robust` + `won_unknown` = `success`. `miss_rate` = missed /
    attackable (None without an attackable state). `won_robust` is a contradiction (a won state
    has a point that changes the action): it must be 0, and is reported, never dropped."""
    attackable, robust, unknown = (verdict == v for v in ("attackable", "robust", "unknown"))
    missed = int((attackable & ~won).sum())
    return {"states": len(verdict), "success": int(won.sum()), "success_share": float(won.mean()),
            "attackable": int(attackable.sum()), "found": int((attackable & won).sum()), "missed": missed,
            "miss_rate": missed / int(attackable.sum()) if attackable.any() else None,
            "won_robust": int((won & robust).sum()), "won_unknown": int((won & unknown).sum())}


@dataclass(frozen=True)
class MinEps:
    """The smallest radius at which each state's action can change lies in (lower, upper]: robust
    (proved) at `lower`, a confirmed counterexample at `upper` (inf: none up to the largest radius
    checked). `stopped`: the bisection met an unknown verdict and kept the bracket it had."""
    lower: np.ndarray    # (N,)
    upper: np.ndarray    # (N,)
    stopped: np.ndarray  # (N,) bool
    broken: int          # states whose grid verdicts break nesting (`grid_bracket`): a bug if not 0
    checks: int          # exact checks run by the bisection (the grid's are reused)
    seconds: float


def grid_bracket(grid: list[float], verdicts: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, int]:
    """Each state's starting bracket from the verdicts at the grid radii (one array per radius): the
    largest radius proved robust (0 if none) and the smallest found attackable (inf if none), and how
    many states break nesting (robust at a radius larger than one where it is attackable: must be 0)."""
    radii = np.asarray(grid, dtype=np.float64)[:, None]
    table = np.stack(verdicts)                                  # (G, N)
    lower = np.where(table == "robust", radii, 0.0).max(axis=0)
    upper = np.where(table == "attackable", radii, np.inf).min(axis=0)
    return lower, upper, int((lower >= upper).sum())


def min_eps(net: nn.Module, kind: str, states: np.ndarray, grid: list[float], verdicts: list[np.ndarray],
            mask: np.ndarray, bounds: tuple[float, float], time_limit: float, steps: int = 8) -> MinEps:
    """Bisection on `exact` for each state's smallest radius that changes its action, started from
    its bracket on the grid (`grid_bracket`) and halved `steps` times where the bracket is finite:
    robust at the midpoint raises `lower`, attackable lowers `upper`, unknown stops that state. States
    robust at every grid radius keep (largest radius, inf); a broken bracket is counted, not bisected."""
    start = time.perf_counter()
    lower, upper, broken = grid_bracket(grid, verdicts)
    stopped = lower >= upper  # a broken bracket (counted in `broken`) is not bisected
    checks = 0
    for _ in range(steps):
        rows = np.flatnonzero(np.isfinite(upper) & ~stopped)
        if not len(rows):
            break
        mid = (lower[rows] + upper[rows]) / 2
        verdict = exact(net, kind, states[rows], mid, mask, *bounds, time_limit=time_limit).verdict
        checks += len(rows)
        lower[rows] = np.where(verdict == "robust", mid, lower[rows])
        upper[rows] = np.where(verdict == "attackable", mid, upper[rows])
        stopped[rows] = verdict == "unknown"
    return MinEps(lower=lower, upper=upper, stopped=stopped, broken=broken, checks=checks,
                  seconds=time.perf_counter() - start)


QUARTILES = (0.25, 0.5, 0.75)


def quartiles(values: np.ndarray) -> list[float]:
    """The 25th, 50th and 75th percentiles as order statistics (no interpolation: inf stays inf, and
    quartiles of lower and upper bounds bound the true quartiles)."""
    return [float(np.quantile(values, q, method="inverted_cdf")) for q in QUARTILES]


def min_eps_summary(found: MinEps, grid: list[float], verdicts: list[np.ndarray], wins: dict[str, np.ndarray],
                    steps: int) -> dict[str, Any]:
    """certify.json's `min_eps`: per state the bracket (None for inf), quartiles of both ends, and on the
    grid alone the quartiles of the smallest radius at which the exact check (`verdicts`, one array per
    grid radius) and each attack (`wins`: name -> (G, N) bool) changed the action (inf where never:
    null in JSON)."""
    radii = np.asarray(grid, dtype=np.float64)[:, None]

    def first(hit: np.ndarray) -> np.ndarray:
        return np.where(hit, radii, np.inf).min(axis=0)

    def listed(values: list[float] | np.ndarray) -> list[float | None]:
        return [None if not np.isfinite(v) else float(v) for v in values]

    on_grid = {"exact": listed(quartiles(first(np.stack(verdicts) == "attackable")))}
    return {
        "steps": steps, "grid": list(grid), "checks": found.checks, "seconds": found.seconds, "broken": found.broken,
        "lower": listed(found.lower), "upper": listed(found.upper),
        "quartiles_lower": listed(quartiles(found.lower)), "quartiles_upper": listed(quartiles(found.upper)),
        "beyond_grid": int((~np.isfinite(found.upper)).sum()), "stopped": int(found.stopped.sum()),
        "unknown_at_max": int((~np.isfinite(found.upper) & (found.lower < max(grid))).sum()),
        "on_grid": on_grid | {name: listed(quartiles(first(won))) for name, won in wins.items()},
    }
