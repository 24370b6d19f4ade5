"""A probe (issue 23, item 1; not a product command): vertex check with the picker's `switch` set here instead of
the fitted 0.3. A held vertex the picker rates below `switch` at the new state is replaced by the picker's best of
its fresh candidates when that one rates higher, and the step's one check is spent on what will be fed. A higher
switch checks the picker's fresh favourite more often; a lower one keeps a held vertex until a check fails. The
picker folder stores its switch, so another value is another attack; this asks whether one would be stronger.
Drives the product's `vertex-check:PICKER` on tuning seeds 900000+; prints the return, the victim's action shares
and the counted queries per step.

    python studies/learned-adversary/pilots/one-query/check_switch.py MODEL EPS PICKER_DIR SWITCH [--episodes 30]
"""

from __future__ import annotations

import numpy as np

from common import arguments, drive_counting, percent, vertex_check


def main() -> None:
    p = arguments(30, "picker")
    p.add_argument("switch", type=float)
    a = p.parse_args()
    victim, env, threat, attack, objective, oracle = vertex_check(a.model, a.eps, a.picker)
    attack.picker.switch = a.switch
    returns, actions = drive_counting(env, victim, attack, objective, oracle, a.episodes)
    share = percent(actions)
    print(f"  switch {a.switch}: return {np.mean(returns):.2f} over seeds 900000-{900000 + a.episodes - 1}, action share % "
          f"(LANE_LEFT, IDLE, LANE_RIGHT, FASTER, SLOWER) {share}, {oracle.total_queries / actions.sum():.2f} queries/step")


if __name__ == "__main__":
    main()
