"""A probe (issue 23, item 1; not a product command): can what one query per step cannot search for be found
offline? Universal perturbations (CopyCAT, Hussenot et al., AAMAS 2020) fitted with training queries.

The victim drives --train episodes (training seeds 0..) under vertex hold or a fitted adversary (the states
an attack leads to); --pool random vertices of the eps-ball are queried at every one of those states. Printed:
the share of states each vertex makes the victim take FASTER (mean, best, 90th percentile), a greedy cover
(each next vertex the one taking FASTER on most states the earlier ones miss), and on tuning seeds
900000..: vertex hold beside a hold over that ranked list (on a miss, the next vertex of the list).

    python studies/learned-adversary/pilots/one-query/universal.py MODEL EPS [--under ADVERSARY_DIR]
"""

from __future__ import annotations

from typing import Any

import numpy as np

from common import FASTER, arguments, drive, setup, show, vertex_hold
from zodrive.attacks.learned import LearnedAdversary, apply_action, free_coordinates


def main() -> None:
    p = arguments()
    p.add_argument("--under", help="a fitted adversary's folder: collect the states it leads to")
    p.add_argument("--train", type=int, default=20)
    p.add_argument("--pool", type=int, default=4096)
    p.add_argument("--k", type=int, default=16)
    a = p.parse_args()
    _, victim, env, threat = setup(a.model, a.eps)
    shape = env.observation_space.shape
    rng = np.random.default_rng(0)
    if a.under:
        adversary, free = LearnedAdversary(threat, adversary=a.under), free_coordinates(threat, shape)
        collect = lambda x, memory: apply_action(threat, x, adversary.actions(x.reshape(1, -1)), free)  # noqa: E731
    else:
        collect = vertex_hold(threat, shape, rng)
    states: list[np.ndarray] = []
    r = drive(env, victim, 0, a.train, collect, states=states)
    print(f"{a.model} eps {a.eps}: {len(states)} states from training seeds 0-{a.train - 1} under "
          f"{a.under or 'vertex hold'} (return {r['return']:.2f}), {a.pool} random vertices queried at each")
    pool = a.eps * rng.choice(np.array([-1.0, 1.0], np.float32), size=(a.pool, *shape)) * threat.mask(shape)
    hits = np.stack([victim.query(threat.project(s[None] + pool, np.repeat(s[None], a.pool, axis=0))).argmax(1)
                     == FASTER for s in states])
    rate = hits.mean(axis=0)
    print(f"  share of states a vertex makes it take FASTER: mean {rate.mean():.1%}, best {rate.max():.1%}, "
          f"90th percentile {np.quantile(rate, 0.9):.1%}")
    order, missed = [], np.ones(len(states), dtype=bool)
    for _ in range(a.k):
        j = int((hits & missed[:, None]).sum(axis=0).argmax())
        order.append(j)
        missed &= ~hits[:, j]
    print(f"  greedy cover by 1 / 2 / 4 / {a.k} vertices: " + " / ".join(
        f"{1 - (~hits[:, order[:n]].any(axis=1)).mean():.1%}" for n in (1, 2, 4, a.k)))
    ranked = pool[order]

    def ranked_hold(x: np.ndarray, memory: dict[str, Any]) -> np.ndarray:
        memory["at"] = (memory.get("at", -1) + 1) % len(ranked) if memory["missed"] or "at" not in memory \
            else memory["at"]
        return threat.project(x + ranked[memory["at"]], x)

    print(f"  tuning seeds 900000-{900000 + a.episodes - 1}:")
    show("vertex hold", drive(env, victim, 900000, a.episodes, vertex_hold(threat, shape, np.random.default_rng(0))))
    show("hold over the ranked list", drive(env, victim, 900000, a.episodes, ranked_hold))


if __name__ == "__main__":
    main()
