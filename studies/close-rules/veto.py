"""How often a shield vetoes models/dqn-close on its own clean trajectory, and what for (a diagnostic):
the bare driver drives seeds 900000-900002 (tuning seeds); at every step the shield's decision on the
same observation is compared with the driver's. Prints the vetoed (proposed, shield's) pairs and the
own lane's pessimistic room [m] at the vetoes.
Usage: python studies/close-rules/veto.py EPS shield|close-shield"""
import collections
import sys

import numpy as np

from zodrive.policies.resolve import load_victim
from zodrive.defense.shield import Shield
from zodrive.envs import load_preset, make_env

preset = load_preset("discrete")
driver = load_victim("models/dqn-close", preset)
names = ["LANE_LEFT", "IDLE", "LANE_RIGHT", "FASTER", "SLOWER"]
shield = Shield(preset, float(sys.argv[1]), sys.argv[2])
vetoes, steps, own = collections.Counter(), 0, []
for seed in (900000, 900001, 900002):
    env = make_env(preset)
    obs, _ = env.reset(seed=seed)
    done = False
    while not done:
        o = obs[None].astype(np.float32)
        a = int(driver.actions(driver.query(o))[0])
        b = int(shield.decide(o, np.array([a]))[0])
        if a != b:
            vetoes[(names[a], names[b])] += 1
            own.append(float(shield.rules.rooms(o)["own"][0]))
        steps += 1
        obs, _, terminated, truncated, _ = env.step(a)  # the bare driver's trajectory
        done = terminated or truncated
print(f"{sys.argv[2]}@{sys.argv[1]}: {steps} steps, {sum(vetoes.values())} vetoed:", vetoes.most_common(8))
print("own room at the vetoes [m], percentiles 10/25/50/75/90:", np.percentile(own, [10, 25, 50, 75, 90]).round(1) if own else None)
