"""How often does a defense change the clean decision of the policy it guards?

The defended system drives clean episodes (tuning seeds 50000+); at every step the bare policy's action on
the raw observation is compared with the action the defended system takes.

    python studies/defenses-field/changes.py --defense smooth@0.02 --episodes 30
"""

from __future__ import annotations

import argparse

import numpy as np

from zodrive.defense import keeps_state, make_defense
from zodrive.envs import load_preset, make_env
from zodrive.policies.policy import resolve

MODEL = "models/zoo/highway-fast-dqn/seed-0"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--defense", required=True)
    parser.add_argument("--episodes", type=int, default=30)
    parser.add_argument("--scenario", default="highway-fast")
    args = parser.parse_args()
    preset = load_preset(args.scenario)
    victim = resolve(MODEL).victim(preset)
    defense = make_defense(args.defense, preset)
    env = make_env(preset)
    changed = steps = 0
    by_action = np.zeros((5, 5), dtype=int)  # bare action -> defended action
    for episode in range(args.episodes):
        obs, _ = env.reset(seed=50000 + episode)
        first, done = True, False
        while not done:
            bare = int(victim.query(obs[None]).argmax())
            if keeps_state(args.defense):
                seen = defense.reset(obs) if first else defense.update(obs)  # type: ignore[union-attr]
                taken = int(victim.query(seen[None]).argmax())
            else:
                taken = int(defense.guard(victim).query(obs[None]).argmax())  # type: ignore[union-attr]
            first = False
            changed += bare != taken
            steps += 1
            by_action[bare, taken] += 1
            obs, _, terminated, truncated, _ = env.step(taken)
            done = terminated or truncated
    print(f"{args.defense}: changes the clean action on {changed} of {steps} steps ({100 * changed / steps:.1f} %), "
          f"{args.episodes} episodes (seeds 50000+)")
    print("bare action (rows) -> defended action (columns), LANE_LEFT IDLE LANE_RIGHT FASTER SLOWER:")
    print(by_action)


if __name__ == "__main__":
    main()
