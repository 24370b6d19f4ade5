"""A probe (issue 23, item 1; not a product command): could vertex check skip the checks its picker is sure of,
and spend the saved queries where a check fails? The victim drives under the product's vertex check with the
picker (`--attack vertex-check:DIR`, one query per step). For analysis only (uncounted, not an attack), at
every step with a held vertex the victim is also asked on it: the probe prints how often held vertices fail
by the picker's rating of them, and, where one fails, how often one of the picker's best k of 64 fresh
vertices works. Tuning seeds 900000.., nothing written.

    python studies/learned-adversary/pilots/one-query/budget.py MODEL EPS PICKER_DIR [--episodes 20]
"""

from __future__ import annotations

import numpy as np

from common import FASTER, Vertices, arguments, drive_attack, vertex_check


def main() -> None:
    p = arguments(20, "picker")
    a = p.parse_args()
    victim, env, threat, attack, objective, oracle = vertex_check(a.model, a.eps, a.picker)
    picker, rng = attack.picker, np.random.default_rng(0)
    v = Vertices(threat, env.observation_space.shape)
    held_rows, topk, ks = [], [], (1, 2, 3, 4, 8)

    def at_state(x: np.ndarray, held: np.ndarray | None) -> None:
        if held is None or np.isnan(held).any():
            return
        works = v.takes(victim, x, held)[0]
        held_rows.append((float(picker.scores(v.fed(x, held))[0]), bool(works)))
        if not works:
            pool = v.fed(x, v.random(rng, 64))
            best = np.argsort(-picker.scores(pool), kind="stable")[:max(ks)]
            hit = victim.query(pool[best]).argmax(axis=1) == FASTER
            topk.append([bool(hit[:k].any()) for k in ks])

    drive_attack(env, victim, attack, objective, oracle, 900000, a.episodes, at_state)
    rated, worked = np.array(held_rows).T
    print(f"  {len(rated)} steps with a held vertex; it failed on {(1 - worked.mean()) * 100:.2f} %")
    for q in (0.5, 0.8, 0.9):
        top = rated >= np.quantile(rated, q)
        print(f"  the top {100 * (1 - q):.0f} % by the picker's rating (>= {np.quantile(rated, q):.3f}) failed on "
              f"{(1 - worked[top].mean()) * 100:.2f} %, the rest on {(1 - worked[~top].mean()) * 100:.2f} %")
    hits = np.array(topk).mean(axis=0) * 100
    print(f"  where it failed ({len(topk)} steps), one of the picker's best k of 64 fresh vertices worked: "
          + ", ".join(f"k={k} {h:.1f} %" for k, h in zip(ks, hits)))


if __name__ == "__main__":
    main()
