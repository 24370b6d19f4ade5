"""Does `baseline:brake-escape` gain on merge by moving back to the right lane after an escape?

The variant takes LANE_RIGHT where brake-escape would brake, the ego is centred in its lane, the
right lane is not blocked beside it, its room ahead exceeds `margin` [m] beyond the rules' safe gap,
and the own lane's room is not negative. Scored on tuning seeds 50030-50129, paired with the brake.

Run: python studies/zoo-recipe/merge_keep_right.py
"""

from __future__ import annotations

import numpy as np

import zodrive
from zodrive.drivers.rules import LANE_RIGHT, SLOWER, BrakeEscape
from zodrive.envs import load_preset
from zodrive.evaluation.stats import paired_difference_ci

SEED, EPISODES = 50_030, 100


def keep_right(margin: float):
    rules = BrakeEscape(load_preset("merge"))

    def decide(obs: np.ndarray) -> int:
        batch = np.asarray(obs, dtype=np.float64).reshape(1, 5, 5)
        r = rules.rooms(batch)
        action = int(rules.actions(batch, r)[0])
        if (action == SLOWER and r["centred"][0] and not r["right_blocked"][0] and r["right"][0] > margin
                and r["own"][0] >= 0):
            return LANE_RIGHT
        return action
    return decide


def main() -> None:
    brake = [e["return"] for e in zodrive.evaluate("baseline:slower", "merge", episodes=EPISODES, seed=SEED).episodes]
    print("| Policy | Return | Collisions | Lane changes | Right-lane share | Δ brake (paired 95% CI) |\n|---|---|---|---|---|---|")
    for label, policy in [("baseline:brake-escape", "baseline:brake-escape")] + [
            (f"keep right, margin {m:g} m", keep_right(m)) for m in (15.0, 0.0, -10.0)]:
        r = zodrive.evaluate(policy, "merge", episodes=EPISODES, seed=SEED)
        mean, low, high = paired_difference_ci([e["return"] for e in r.episodes], brake)
        print(f"| {label} | {r.summary['mean_return']:.2f} | {100 * r.summary['collision_rate']:.0f} % | "
              f"{np.mean([e['lane_changes'] for e in r.episodes]):.2f} | "
              f"{np.mean([e['right_lane_share'] for e in r.episodes]):.2f} | {mean:+.2f} ({low:+.2f} to {high:+.2f}) |")


if __name__ == "__main__":
    main()
