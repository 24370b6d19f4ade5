"""The tuning sweep behind baseline:close-rules: baseline:rules with its margin [m], IDM time gap [s] and
assumed own speed [m/s] overridden, on tuning seeds only.
Usage: python studies/close-rules/sweep.py FIRST_SEED N MARGIN,HEADWAY,ASSUMED ..."""
import sys
import numpy as np
import zodrive.drivers.rules as R
from zodrive.envs.presets import load_preset, make_env
preset = load_preset("discrete")
first, n = int(sys.argv[1]), int(sys.argv[2])
grid = [tuple(float(v) for v in g.split(",")) for g in sys.argv[3:]]  # margin,headway,assumed
for margin, headway, assumed in grid:
    R.ASSUMED_SPEED = assumed  # read at call time; margin and headway are the rules' own parameters
    rules = R.ObservationRules(preset, headway=headway, margin=margin)
    rets, crashes, speeds, lc = [], 0, [], 0
    for seed in range(first, first + n):
        env = make_env(preset)
        obs, _ = env.reset(seed=seed)
        done, total = False, 0.0
        while not done:
            a = int(rules.actions(obs[None])[0])
            obs, r, te, tr, _ = env.step(a)
            total += r; speeds.append(env.unwrapped.vehicle.speed); done = te or tr
        rets.append(total); crashes += bool(env.unwrapped.vehicle.crashed)
    print(f"margin {margin} headway {headway} assumed {assumed}: mean {np.mean(rets):.2f}, crashes {crashes}/{n}, speed {np.mean(speeds):.2f}", flush=True)
