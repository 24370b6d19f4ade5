"""A probe (issue 23, item 1; not a product command): should vertex check's check also accept IDLE?
In the discrete preset the ego's target speeds are [20, 25, 30] m/s and it starts at 25: one FASTER puts it
at the top, where FASTER and IDLE are the same command. The observation cannot tell (ego vx is clipped at
20 m/s), so the strict check rejects held vertices on which the victim would take IDLE and swaps them for a
fresh vertex fed unasked, which the victim may brake on. Variants of the check's rule, each driving the
product's `vertex-check:PICKER` (its counted queries, its picker, its random streams) on tuning seeds:

  strict   FASTER only (the product; must print the product's return on the same seeds)
  always   FASTER or IDLE, everywhere
  tracked  FASTER, or IDLE while the attacker believes the ego is at the top speed: from a confirmed FASTER
           until a step whose action it does not know (a vertex fed unasked); what a one-query attacker knows
  truth    FASTER, or IDLE where the simulator says the ego is at the top speed (an upper bound)

    python studies/learned-adversary/pilots/one-query/idle.py MODEL EPS PICKER_DIR RULE [--episodes 30]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from common import FASTER, arguments, drive_counting, percent, vertex_check
from zodrive.attacks.objectives import DiscreteTargeted

IDLE = 1
TOP = [False]  # set before each step: whether the check also accepts IDLE


@dataclass(frozen=True)
class FasterOrIdle(DiscreteTargeted):
    """FASTER, or IDLE while TOP[0] (the picker's goal is still FASTER: it ranks fresh vertices for it)."""

    def success(self, out: torch.Tensor, clean: torch.Tensor) -> torch.Tensor:
        a = out.argmax(dim=-1)
        return (a == self.target) | ((a == IDLE) & TOP[0])


def main() -> None:
    p = arguments(30, "picker")
    p.add_argument("rule", choices=["strict", "always", "tracked", "truth"])
    a = p.parse_args()
    victim, env, threat, attack, objective, oracle = vertex_check(a.model, a.eps, a.picker)
    if a.rule != "strict":
        objective = FasterOrIdle(target=FASTER)
    belief = {"top": False}

    def before(x: np.ndarray, held: np.ndarray | None) -> None:
        if held is None:  # an episode's start: the ego is at 25 m/s
            belief["top"] = False
        TOP[0] = bool({"strict": False, "always": True, "tracked": belief["top"],
                  "truth": env.unwrapped.vehicle.speed_index == len(env.unwrapped.vehicle.target_speeds) - 1}[a.rule])

    def after(result) -> None:
        out = result.adv_outputs[0]
        if np.isnan(out).any():  # a vertex fed unasked: its action is unknown, the ego may have braked
            belief["top"] = False
        elif out.argmax() == FASTER:
            belief["top"] = True

    returns, actions = drive_counting(env, victim, attack, objective, oracle, a.episodes, before, after)
    share = percent(actions)
    print(f"  rule {a.rule}: return {np.mean(returns):.2f} over seeds 900000-{900000 + a.episodes - 1}, mean length "
          f"{actions.sum() / a.episodes:.1f}, action share % (LANE_LEFT, IDLE, LANE_RIGHT, FASTER, SLOWER) {share}, "
          f"{oracle.total_queries / actions.sum():.2f} queries/step")


if __name__ == "__main__":
    main()
