"""A probe (issue 23, item 1; not a product command): the fitted adversary with vertex check's rule, at one query
per step. On models/dqn-robust at eps 0.05 the fitted start (with the fallback target) lets the victim brake on
5-11 % of steps, random search with the fallback on 2.4-3.5 %. Here the step's one query checks the fitted
adversary's perturbation first; where the victim would brake on it (--trigger brake) or not take FASTER
(--trigger miss), a random vertex of the ball is fed instead, unasked: a fresh one each time (--hold off), or
one kept until a check says the adversary works again (--hold on). Tuning seeds 900000.., nothing written.

    python studies/learned-adversary/pilots/one-query/precheck.py MODEL EPS ADVERSARY_DIR [--trigger brake]
"""

from __future__ import annotations

from typing import Any

import numpy as np

from common import FASTER, arguments, drive, setup, show
from zodrive.attacks.learned import LearnedAdversary, apply_action, free_coordinates

SLOWER = 4


def main() -> None:
    p = arguments(folder="adversary")
    p.add_argument("--trigger", choices=("miss", "brake"), default="brake")
    a = p.parse_args()
    _, victim, env, threat = setup(a.model, a.eps)
    adversary = LearnedAdversary(threat, adversary=a.adversary)
    shape = env.observation_space.shape
    free, mask = free_coordinates(threat, shape), threat.mask(shape)
    print(f"{a.model} eps {a.eps} under {a.adversary}, seeds 900000-{900000 + a.episodes - 1}, trigger {a.trigger}:")
    for hold in (False, True):
        rng = np.random.default_rng(0)

        def choose(x: np.ndarray, memory: dict[str, Any]) -> np.ndarray:
            fitted = apply_action(threat, x, adversary.actions(x.reshape(1, -1)), free)
            act = int(victim.query(fitted)[0].argmax())  # the step's one query
            bad = act == SLOWER if a.trigger == "brake" else act != FASTER
            if not bad:
                memory["held"] = None
                return fitted
            if memory.get("held") is None or not hold:
                memory["held"] = threat.eps * rng.choice(np.array([-1.0, 1.0], np.float32), size=shape) * mask
            return threat.project(x + memory["held"], x)

        show(f"checked, a random vertex where it fails ({'kept' if hold else 'fresh'})",
             drive(env, victim, 900000, a.episodes, choose))


if __name__ == "__main__":
    main()
