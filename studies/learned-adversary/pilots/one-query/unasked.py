"""A probe (issue 23, item 1; not a product command): vertex check (`--attack vertex-check:DIR`) feeds a fresh
vertex, unasked, where its check says the held one fails; what fresh vertex works most often there? The victim
drives under the product's vertex check (its own counted query and random streams). At every step where the
held vertex fails at the new state, the victim is also asked, for analysis only (uncounted, not an attack), on:
  picker-64    the picker's best of 64 random vertices (what vertex check feeds),
  picker-1024  the picker's best of 1024,
  recent       the last vertex confirmed before the held one (a memory of this episode's winners),
  recent-best  the picker's best of the last 8 distinct confirmed vertices,
  near-h       the picker's best of 64 copies of the held vertex with 10 % of its signs flipped,
  gradient     the vertex the picker's gradient points to at the failed point,
  any-1024     whether any of those 1024 random vertices works (what a search could find).
Tuning seeds 900000.., nothing written.

    python studies/learned-adversary/pilots/one-query/unasked.py MODEL EPS PICKER_DIR [--episodes 30]
"""

from __future__ import annotations

import functools

import numpy as np
import torch

from common import Vertices, arguments, drive_attack, vertex_check


def main() -> None:
    p = arguments(30, "picker")
    a = p.parse_args()
    victim, env, threat, attack, objective, oracle = vertex_check(a.model, a.eps, a.picker)
    picker, rng = attack.picker, np.random.default_rng(0)
    v = Vertices(threat, env.observation_space.shape)
    fed, dim, eps, mask = v.fed, v.dim, v.eps, v.mask
    names = ("picker-64", "picker-1024", "recent", "recent-best", "near-h", "gradient", "any-1024")
    hits = {n: 0 for n in names}
    failed, steps, winners = 0, 0, []

    works = functools.partial(v.takes, victim)

    def best(x: np.ndarray, deltas: np.ndarray) -> np.ndarray:
        return deltas[int(picker.scores(fed(x, deltas)).argmax())]

    def at_state(x: np.ndarray, held: np.ndarray | None) -> None:
        nonlocal failed, steps
        steps += 1
        if held is None:  # an episode begins
            winners.clear()
        if held is None or np.isnan(held).any() or works(x, held)[0]:
            return
        failed += 1
        h = held[0]
        pool = v.random(rng, 1024)
        ok = works(x, pool)
        hits["picker-64"] += bool(works(x, best(x, pool[:64])[None])[0])
        hits["picker-1024"] += bool(ok[int(picker.scores(fed(x, pool)).argmax())])
        older = [w for w in winners if not np.array_equal(w, h)]
        hits["recent"] += bool(older) and bool(works(x, older[-1][None])[0])
        hits["recent-best"] += bool(older) and bool(works(x, best(x, np.stack(older[-8:]))[None])[0])
        flips = rng.random((64, dim)) < 0.1
        hits["near-h"] += bool(works(x, best(x, np.where(flips, -h, h) * mask)[None])[0])
        point = torch.from_numpy(fed(x, h[None]).reshape(1, -1)).requires_grad_(True)
        picker.net(point).sum().backward()
        hits["gradient"] += bool(works(x, (eps * np.sign(point.grad.numpy()[0]) * mask)[None])[0])
        hits["any-1024"] += bool(ok.any())

    def after(result) -> None:  # a vertex the check confirmed joins the episode's winners
        if result.success[0] and (not winners or not np.array_equal(winners[-1], attack.carried[0])):
            winners.append(attack.carried[0].copy())

    returns = drive_attack(env, victim, attack, objective, oracle, 900000, a.episodes, at_state, after)
    print(f"  vertex check: return {np.mean(returns):.2f} over {a.episodes} episodes, {steps} steps; the held vertex "
          f"failed its check on {failed} ({failed / steps * 100:.1f} %)")
    for n in names:
        print(f"  {n}: works on {hits[n] / max(failed, 1) * 100:.1f} % of those steps")


if __name__ == "__main__":
    main()
