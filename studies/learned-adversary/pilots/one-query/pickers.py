"""A probe (issue 23, item 1; not a product command): vertex hold with several pickers (`zodrive picker-train`
fits) whose ratings are averaged, against each picker alone, at one query per step. The rule is
`--attack vertex-hold:DIR`'s: hold the vertex while the victim takes FASTER; where a new one is needed, or the
held one rates below the pickers' `switch` at the new state, feed the best-rated of `candidates` random
vertices. Seeds --seed0.., nothing written.

    python studies/learned-adversary/pilots/one-query/pickers.py MODEL EPS PICKER_DIR [PICKER_DIR ...]
"""

from __future__ import annotations

from typing import Any

import numpy as np

from common import arguments, drive, setup, show
from zodrive.attacks.picker import Picker


def main() -> None:
    p = arguments()
    p.add_argument("pickers", nargs="+")
    p.add_argument("--seed0", type=int, default=900000)
    p.add_argument("--alone", action="store_true", help="also each picker alone")
    p.add_argument("--paired", help="an evaluation folder on the same seeds: the paired difference against it")
    a = p.parse_args()
    _, victim, env, threat = setup(a.model, a.eps)
    pickers = [Picker.load(d)[0] for d in a.pickers]
    shape = env.observation_space.shape
    mask = threat.mask(shape)
    k, switch = pickers[0].candidates, pickers[0].switch
    print(f"{a.model} eps {a.eps}, seeds {a.seed0}-{a.seed0 + a.episodes - 1}, best of {k}, switch {switch}:")

    def chooser(use: list[Picker]) -> Any:
        rng = np.random.default_rng(0)

        def rate(fed: np.ndarray) -> np.ndarray:
            return np.mean([q.scores(fed) for q in use], axis=0)

        def choose(x: np.ndarray, memory: dict[str, Any]) -> np.ndarray:
            held = memory.get("held")
            rating = -np.inf
            if held is not None and memory["missed"]:
                held = None
            if held is not None:
                rating = float(rate(threat.project(x + held, x))[0])
                if rating >= switch:
                    return threat.project(x + held, x)
            pool = threat.eps * rng.choice(np.array([-1.0, 1.0], np.float32), size=(k, *shape)) * mask
            scores = rate(threat.project(np.repeat(x, k, axis=0) + pool, np.repeat(x, k, axis=0)))
            if held is None or scores.max() > rating:
                held = pool[int(scores.argmax())]
            memory["held"] = held
            return threat.project(x + held, x)
        return choose

    if a.alone:
        for d, q in zip(a.pickers, pickers):
            show(f"{d} alone", drive(env, victim, a.seed0, a.episodes, chooser([q])))
    r = drive(env, victim, a.seed0, a.episodes, chooser(pickers))
    show(f"the {len(pickers)} pickers' mean rating", r)
    if a.paired:
        from zodrive.evaluation import store
        from zodrive.evaluation.stats import paired_difference_ci

        other = {row["seed"]: row["return"] for row in store.episodes(a.paired)}  # its folder, or packed
        diff, low, high = paired_difference_ci(r["returns"], [other[a.seed0 + e] for e in range(a.episodes)])
        print(f"  paired, mean rating - {a.paired}: {diff:+.2f} [{low:+.2f}, {high:+.2f}] over {a.episodes} seeds")


if __name__ == "__main__":
    main()
