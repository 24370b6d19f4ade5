"""A probe (issue 23, item 1; not a product command): a fitted adversary that uses its one answer per step.
After a step on which the victim did not take FASTER, the adversary's sign pattern is fed with --m random
coordinates flipped (a new draw each such step); else its own perturbation. --m 0 is the fitted adversary
(signs of its action: at the box's corners already). Tuning seeds 900000.., nothing written.

    python studies/learned-adversary/pilots/one-query/closed_loop.py MODEL EPS ADVERSARY_DIR [--m 1 3]
"""

from __future__ import annotations

from typing import Any

import numpy as np

from common import arguments, drive, setup, show
from zodrive.attacks.learned import LearnedAdversary, apply_action, free_coordinates


def main() -> None:
    p = arguments(folder="adversary")
    p.add_argument("--m", type=int, nargs="+", default=[1, 3])
    a = p.parse_args()
    _, victim, env, threat = setup(a.model, a.eps)
    adversary = LearnedAdversary(threat, adversary=a.adversary)
    free = free_coordinates(threat, env.observation_space.shape)
    print(f"{a.model} eps {a.eps} under {a.adversary}, tuning seeds 900000-{900000 + a.episodes - 1}:")
    for m in [0, *a.m]:
        rng = np.random.default_rng(0)

        def choose(x: np.ndarray, memory: dict[str, Any]) -> np.ndarray:
            signs = np.sign(adversary.actions(x.reshape(1, -1)))
            if memory["missed"] and m:
                signs[0, rng.choice(len(free), m, replace=False)] *= -1
            return apply_action(threat, x, signs, free)

        show(f"flip {m} after a miss" if m else "fitted adversary (signs)", drive(env, victim, 900000, a.episodes, choose))


if __name__ == "__main__":
    main()
