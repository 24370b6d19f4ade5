"""baseline:rules with the safe gap at (a) the assumed 25 m/s, (b) the ego's target speed
(what one integer of memory, counting its own FASTER / SLOWER, would know), (c) its true speed (read from the simulator). Tuning seeds only.
Usage: python studies/planner/known_speed.py {assumed,target,true} FIRST_SEED N"""
import sys
import numpy as np
import zodrive.drivers.rules as R
from zodrive.envs.presets import load_preset, make_env

mode = sys.argv[1]; seeds = range(int(sys.argv[2]), int(sys.argv[2]) + int(sys.argv[3]))
preset = load_preset("discrete")
rules = R.ObservationRules(preset)
rets, crashes, speeds = [], 0, []
for seed in seeds:
    env = make_env(preset)
    obs, _ = env.reset(seed=seed)
    done, total = False, 0.0
    while not done:
        v = env.unwrapped.vehicle
        R.ASSUMED_SPEED = {"assumed": 25.0, "target": float(v.target_speed), "true": float(v.speed)}[mode]
        obs, r, terminated, truncated, info = env.step(int(rules.actions(obs[None])[0]))
        total += r; speeds.append(env.unwrapped.vehicle.speed)
        done = terminated or truncated
    rets.append(total); crashes += bool(env.unwrapped.vehicle.crashed)
    print(seed, round(total, 2), env.unwrapped.vehicle.crashed, flush=True)
print(f"{mode}: mean {np.mean(rets):.2f} over {len(rets)}, crashes {crashes}, speed {np.mean(speeds):.2f}")
