"""Why `dqn-close`'s exact check leaves states unknown: the MILPs themselves, under three solvers.

    python studies/exact-sandwich/hard_states.py [--states 40] [--eps 0.01] [--long 90] [--scip 30]

On the first `--states` clean states of `dqn-close` (its first clean episode from seed 100000, as
`zodrive certify` draws them) at radius `--eps`:

1. the shipped exact check (`exact.exact`) at 2 s per state: robust / attackable / unknown;
2. on the first two states it leaves unknown, per competing action j that CROWN does not rule out:
   - how many hidden ReLUs are unstable with CROWN's bounds, and with each second-layer neuron's
     bounds tightened by linear programs over the first layer's triangle relaxation (the LP-optimal
     bounds that alpha-CROWN approaches): is the big-M encoding's looseness the problem?
   - HiGHS (scipy's `milp`) on the feasibility form (the margin score(j) - score(a*) >= 0 added as a
     constraint; infeasible = robust), with `--long` seconds;
   - SCIP (`pyscipopt`, if installed: `pip install pyscipopt`, not a zodrive dependency) on the
     same program with `--scip` seconds, and the dual bound it proved on the margin.

A study, not the product: it asks whether a stronger off-the-shelf solver or tighter big-M bounds
would decide the states the shipped check leaves unknown (issue 66's goal).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch
from scipy.optimize import LinearConstraint, linprog, milp

from zodrive.attacks.spec import AttackSpec
from zodrive.envs import scenario
from zodrive.evaluation.certify import box_of, crown_pre, first_states, margins
from zodrive.evaluation.exact import _Program, exact, exact_network
from zodrive.policies.loading import load_network
from zodrive.policies.resolve import resolve_scenario
from zodrive.policies.victims import network_victim

MODEL = "models/dqn-close/model.zip"


def lp_tightened(affine: list, lo: np.ndarray, hi: np.ndarray, l1: np.ndarray, u1: np.ndarray,
                 l2: np.ndarray, u2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Second-layer pre-activation bounds by LP over the first layer's triangle relaxation."""
    w1, b1 = (t.numpy().astype(np.float64) for t in affine[0])
    w2, b2 = (t.numpy().astype(np.float64) for t in affine[1])
    n0, n1 = len(lo), len(l1)
    rows, rhs, eq_rows, eq_rhs = [], [], [], []
    bounds: list[tuple[float | None, float | None]] = [(lo[i], hi[i]) for i in range(n0)]
    for j in range(n1):
        if l1[j] >= 0:    # active: h = z
            e = np.zeros(n0 + n1)
            e[:n0], e[n0 + j] = -w1[j], 1.0
            eq_rows.append(e)
            eq_rhs.append(b1[j])
            bounds.append((None, None))
        elif u1[j] <= 0:  # inactive: h = 0
            bounds.append((0.0, 0.0))
        else:             # h >= z, h <= u (z - l) / (u - l), h >= 0
            bounds.append((0.0, None))
            e = np.zeros(n0 + n1)
            e[:n0], e[n0 + j] = w1[j], -1.0
            rows.append(e)
            rhs.append(-b1[j])
            s = u1[j] / (u1[j] - l1[j])
            e = np.zeros(n0 + n1)
            e[:n0], e[n0 + j] = -s * w1[j], 1.0
            rows.append(e)
            rhs.append(s * (b1[j] - l1[j]))
    low, high = l2.copy(), u2.copy()
    for j in np.flatnonzero((l2 < 0) & (u2 > 0)):
        c = np.zeros(n0 + n1)
        c[n0:] = w2[j]
        kw = dict(A_ub=np.array(rows), b_ub=np.array(rhs), A_eq=np.array(eq_rows) if eq_rows else None,
                  b_eq=np.array(eq_rhs) if eq_rhs else None, bounds=bounds, method="highs")
        low[j] = linprog(c, **kw).fun + b2[j]
        high[j] = -linprog(-c, **kw).fun + b2[j]
    return low, high


def scip(program: _Program, objective: np.ndarray, const: float, seconds: float) -> str:
    """SCIP on the feasibility form; its status and the dual bound it proved on the margin."""
    try:
        from pyscipopt import Model, quicksum
    except ImportError:
        return "SCIP: pyscipopt not installed"
    m = Model()
    m.hideOutput()
    m.setParam("limits/time", seconds)
    v = [m.addVar(lb=program.bounds.lb[k], ub=program.bounds.ub[k],
                  vtype="B" if program.integrality[k] else "C") for k in range(program.n)]
    for r in range(len(program.row_lo)):
        e = quicksum(program.matrix[r, k] * v[k] for k in np.flatnonzero(program.matrix[r]))
        if np.isfinite(program.row_lo[r]):
            m.addCons(e >= program.row_lo[r])
        if np.isfinite(program.row_hi[r]):
            m.addCons(e <= program.row_hi[r])
    margin = quicksum(objective[k] * v[k] for k in np.flatnonzero(objective))
    m.addCons(margin >= -const)
    m.setObjective(margin, "maximize")
    start = time.perf_counter()
    m.optimize()
    status = m.getStatus()
    proved = "" if status == "infeasible" else f", margin <= {m.getDualbound() + const:.3f}"
    return f"SCIP {status} in {time.perf_counter() - start:.1f} s{proved}"


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--states", type=int, default=40)
    p.add_argument("--eps", type=float, default=0.01)
    p.add_argument("--long", type=float, default=90.0)
    p.add_argument("--scip", type=float, default=30.0)
    args = p.parse_args()
    preset, _ = resolve_scenario(MODEL, None, [])
    network = load_network(MODEL, preset)
    net = network.net
    victim = network_victim(net, network.kind, network.obs_shape)
    states, _ = first_states(preset, victim, 100000, 1, args.states)
    env = scenario(preset)
    mask = AttackSpec(eps=args.eps).threat(env.features, env.bounds).mask(states.shape[1:])
    low_b, high_b = env.bounds
    start = time.perf_counter()
    found = exact(net, "discrete", states, args.eps, mask, low_b, high_b, time_limit=2.0)
    counts = {v: int((found.verdict == v).sum()) for v in ("robust", "attackable", "unknown")}
    print(f"{MODEL}, eps {args.eps}, first {len(states)} clean states, exact check at 2 s/state: {counts} "
          f"({time.perf_counter() - start:.0f} s)")
    affine = exact_network(net, "discrete")
    w, b = (t.numpy() for t in affine[-1])
    for i in np.flatnonzero(found.verdict == "unknown")[:2]:
        flat, lo, hi = box_of(states[i:i + 1], np.full((1, 1), args.eps), mask, low_b, high_b)
        with torch.no_grad():
            a = int(net(flat.float()).argmax(1))
            pre = crown_pre(affine, lo, hi)
            lower = margins(net, torch.tensor([a]), lo, hi, pre)[0].numpy()
        pre_np = [(lb[0].numpy(), ub[0].numpy()) for lb, ub in pre]
        unstable = [int(((lb < 0) & (ub > 0)).sum()) for lb, ub in pre_np]
        t0 = time.perf_counter()
        l2, u2 = lp_tightened(affine, lo[0].numpy(), hi[0].numpy(), *pre_np[0], *pre_np[1])
        print(f"state {i}: action {a}; unstable ReLUs with CROWN's bounds {unstable[0]} + {unstable[1]}; "
              f"layer 2 with LP-tightened bounds {int(((l2 < 0) & (u2 > 0)).sum())} "
              f"({time.perf_counter() - t0:.1f} s of LPs)")
        program = _Program(affine, pre_np, lo[0].numpy(), hi[0].numpy())
        for j in [j for j in range(len(w)) if j != a and lower[j] <= 0]:
            c = w[j] - w[a]
            const = float(b[j] - b[a]) + float(c @ program.const)
            objective = c @ program.expr
            t0 = time.perf_counter()
            res = milp(np.zeros(program.n), integrality=program.integrality, bounds=program.bounds,
                       constraints=[LinearConstraint(program.matrix, program.row_lo, program.row_hi),
                                    LinearConstraint(objective[None], -const, np.inf)],
                       options={"time_limit": args.long})
            status = {0: "decided", 1: "time limit", 2: "infeasible (robust)"}.get(res.status, str(res.status))
            print(f"  j={j}: CROWN margin >= {lower[j]:.3f}; HiGHS feasibility: {status} in "
                  f"{time.perf_counter() - t0:.1f} s; {scip(program, objective, const, args.scip)}", flush=True)


if __name__ == "__main__":
    main()
