"""A probe (issue 23, item 1; not a product command): the fitted adversary for FASTER, and vertex hold for
"not braking" while it misses, at one query per step. On models/dqn-robust at eps 0.05 the fitted start takes
the victim to FASTER on about as many steps as random search does (14.5 % against 15.0 %, tuning seeds), but
the victim brakes on about 15 % of steps under it, against 2.4-3.5 % under random search with the fallback;
vertex hold with `--target not:SLOWER` keeps it off the brake on 96 % of steps. Rule: feed the adversary's
perturbation; after a step on which it did not give FASTER (--trigger miss) or gave SLOWER (--trigger brake),
feed a held vertex (kept while the victim does not brake, else a fresh random one) for --m steps, then the
adversary again. Tuning seeds 900000.., nothing written.

    python studies/learned-adversary/pilots/one-query/switch.py MODEL EPS ADVERSARY_DIR [--m 1 3 10] [--trigger miss]
"""

from __future__ import annotations

from typing import Any

import numpy as np

from common import FASTER, arguments, drive, setup, show
from zodrive.attacks.learned import LearnedAdversary, apply_action, free_coordinates

SLOWER = 4


def main() -> None:
    p = arguments(folder="adversary")
    p.add_argument("--m", type=int, nargs="+", default=[1, 3, 10])
    p.add_argument("--trigger", choices=("miss", "brake"), default="miss")
    p.add_argument("--seed0", type=int, default=900000)
    a = p.parse_args()
    _, victim, env, threat = setup(a.model, a.eps)
    adversary = LearnedAdversary(threat, adversary=a.adversary)
    shape = env.observation_space.shape
    free = free_coordinates(threat, shape)
    mask = threat.mask(shape)
    print(f"{a.model} eps {a.eps} under {a.adversary}, seeds {a.seed0}-{a.seed0 + a.episodes - 1}, trigger {a.trigger}:")
    for m in [0, *a.m]:
        rng = np.random.default_rng(0)

        def choose(x: np.ndarray, memory: dict[str, Any]) -> np.ndarray:
            last, mode = memory.get("action"), memory.get("mode", "adversary")
            if mode == "adversary" and last is not None and m and (
                    last != FASTER if a.trigger == "miss" else last == SLOWER):
                memory["mode"], memory["left"] = "hold", m
            elif mode == "hold":
                if last == SLOWER:
                    memory["held"] = None
                memory["left"] -= 1
                if memory["left"] <= 0:
                    memory["mode"] = "adversary"
            if memory.get("mode", "adversary") == "adversary":
                return apply_action(threat, x, adversary.actions(x.reshape(1, -1)), free)
            if memory.get("held") is None:
                memory["held"] = threat.eps * rng.choice(np.array([-1.0, 1.0], np.float32), size=shape) * mask
            return threat.project(x + memory["held"], x)

        show(f"hold for {m} steps after a {a.trigger}" if m else "fitted adversary alone",
             drive(env, victim, a.seed0, a.episodes, choose))


if __name__ == "__main__":
    main()
