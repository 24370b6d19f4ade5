"""A probe (issue 23, item 1; not a product command): PA-AD's split into a director, which picks the action
the victim should take, and an actor, which makes it take it. Here the director is a rule that needs no
query (a lane change towards a car beside the ego in the next lane, |dx| < --beside m, else FASTER) and the
actor is vertex hold (one query per step). If a lane change into a car beside were reachable, the crash
would come sooner than by speeding into the car ahead. Tuning seeds 900000.., nothing written.

    python studies/learned-adversary/pilots/one-query/director.py MODEL EPS [--episodes 30] [--beside 5]
"""

from __future__ import annotations


import numpy as np

from common import FASTER, arguments, drive, setup, show, vertex_hold
from zodrive.drivers.rules import LANE_LEFT, LANE_RIGHT, LANE_WIDTH, ObservationRules


def main() -> None:
    p = arguments()
    p.add_argument("--beside", type=float, default=5.0)
    a = p.parse_args()
    preset, victim, env, threat = setup(a.model, a.eps)
    rules = ObservationRules(preset, 0.0)

    def crash_director(x: np.ndarray) -> int:
        r = rules.rooms(x)
        others = (x[0] * rules.scale[None])[1:]
        for side, action, offset in (("left", LANE_LEFT, -1), ("right", LANE_RIGHT, 1)):
            beside = ((others[:, 0] > 0.5) & (np.abs(others[:, 2] - offset * LANE_WIDTH) < LANE_WIDTH / 2)
                      & (np.abs(others[:, 1]) < a.beside))
            if beside.any() and r[f"{side}_exists"][0]:
                return action
        return FASTER

    shape = env.observation_space.shape
    print(f"{a.model} eps {a.eps}, tuning seeds 900000-{900000 + a.episodes - 1}, vertex hold toward:")
    show("FASTER always (= --attack vertex-hold)", drive(env, victim, 900000, a.episodes,
                                                          vertex_hold(threat, shape, np.random.default_rng(0))))
    show(f"a lane change towards a car beside (|dx| < {a.beside} m), else FASTER",
         drive(env, victim, 900000, a.episodes, vertex_hold(threat, shape, np.random.default_rng(0)),
               target=crash_director))


if __name__ == "__main__":
    main()
