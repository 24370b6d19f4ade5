"""A probe (issue 23, item 1; not a product command): several fitted adversaries (training seeds), one query
per step. Each step feeds one adversary's perturbation; after a miss (the victim did not take FASTER) the next
adversary in turn takes over, and one that works is kept, as vertex hold keeps a vertex. For analysis only
(extra queries, not an attack) it also counts on how many of the steps driven under that rule each adversary,
and any of them, would have given FASTER. Tuning seeds 900000.., nothing written.

    python studies/learned-adversary/pilots/one-query/ensemble.py MODEL EPS ADVERSARY_DIR [ADVERSARY_DIR ...]
"""

from __future__ import annotations

from typing import Any

import numpy as np

from common import FASTER, arguments, drive, setup, show
from zodrive.attacks.learned import LearnedAdversary, apply_action, free_coordinates


def main() -> None:
    p = arguments()
    p.add_argument("adversaries", nargs="+")
    a = p.parse_args()
    _, victim, env, threat = setup(a.model, a.eps)
    advs = [LearnedAdversary(threat, adversary=d) for d in a.adversaries]
    free = free_coordinates(threat, env.observation_space.shape)
    print(f"{a.model} eps {a.eps}, tuning seeds 900000-{900000 + a.episodes - 1}:")

    def fed(i: int, x: np.ndarray) -> np.ndarray:
        return apply_action(threat, x, advs[i].actions(x.reshape(1, -1)), free)

    for i, d in enumerate(a.adversaries):
        show(f"adversary {i} alone ({d})", drive(env, victim, 900000, a.episodes, lambda x, m, i=i: fed(i, x)))
    would = np.zeros((0, len(advs)), bool)

    def choose(x: np.ndarray, memory: dict[str, Any]) -> np.ndarray:
        nonlocal would
        points = [fed(i, x) for i in range(len(advs))]
        took = np.array([int(victim.query(f)[0].argmax()) == FASTER for f in points])  # analysis only
        would = np.vstack([would, took])
        k = memory.get("k", 0)
        if memory["missed"] and "k" in memory:
            k = (k + 1) % len(advs)
        memory["k"] = k
        return points[k]

    show("switch to the next adversary after a miss", drive(env, victim, 900000, a.episodes, choose))
    print(f"  on those {len(would)} steps, FASTER from each adversary: "
          f"{np.round(would.mean(0) * 100, 1).tolist()} %, from any: {would.any(1).mean() * 100:.1f} %")


if __name__ == "__main__":
    main()
