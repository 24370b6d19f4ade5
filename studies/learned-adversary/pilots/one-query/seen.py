"""A probe (issue 23, item 1; not a product command): what if vertex check knew, without a query, whether the
victim took FASTER on the vertex it fed unasked at the last step? The clean observation that follows shows
the car's move (a braking car slows down), so an attacker watching the road learns it for free; here the
probe reads the action itself, an upper bound on what watching could give. Rule (one query per step, as
vertex check): check the vertex about to be fed and, where the check fails, feed the picker's next-best of
the same 64 unasked; but where the vertex about to be fed is one fed unasked at the last step and known to
have failed there, check the picker's best fresh vertex instead of it. Beside it, the product's rule in the
same loop. Tuning seeds 900000.., nothing written.

    python studies/learned-adversary/pilots/one-query/seen.py MODEL EPS PICKER_DIR [--episodes 30]
"""

from __future__ import annotations

from typing import Any

import numpy as np

from common import FASTER, Vertices, arguments, drive, setup, show
from zodrive.attacks.picker import Picker


def main() -> None:
    p = arguments(30, "picker")
    a = p.parse_args()
    _, victim, env, threat = setup(a.model, a.eps)
    picker, _ = Picker.load(a.picker)
    v = Vertices(threat, env.observation_space.shape)
    fed = v.fed

    for seen in (False, True):
        rng = np.random.default_rng(0)

        def ranked(x: np.ndarray) -> np.ndarray:
            pool = v.random(rng, 64)
            return pool[np.argsort(-picker.scores(fed(x, pool)), kind="stable")]

        def choose(x: np.ndarray, memory: dict[str, Any]) -> np.ndarray:
            held, unasked = memory.get("held"), memory.get("unasked", False)
            if held is None or (seen and unasked and memory["missed"]):
                order = ranked(x)
                candidate, spare = order[0], order[1]
            else:
                candidate, spare = held, None
            if victim.query(fed(x, candidate[None]))[0].argmax() == FASTER:  # the step's one query
                memory["held"], memory["unasked"] = candidate, False
            else:
                memory["held"], memory["unasked"] = (ranked(x)[0] if spare is None else spare), True
            return fed(x, memory["held"][None])

        show("seen: a vertex known to have failed is not checked again" if seen else "vertex check's rule",
             drive(env, victim, 900000, a.episodes, choose))


if __name__ == "__main__":
    main()
