"""What a DQN driver on the discrete preset could reach (issue 22): a rollout planner that reads the simulator.

Not a zodrive driver (it copies the environment, which no policy can): at every step each of the five
meta-actions is taken in a deep copy of the environment, followed by `baseline:rules` for H - 1 more
steps; a crash scores -1000 (+ the step it came at), ties go to the rules' own action. H = 0 is the rules.
Usage: python studies/finetune/planner_probe.py H SEED[,SEED...]   (one line per episode)
"""
import copy, sys, time
import numpy as np
from zodrive.envs import load_preset, make_env
from zodrive.drivers.rules import ObservationRules

H = int(sys.argv[1]); seeds = [int(s) for s in sys.argv[2].split(",")]
preset = load_preset("discrete")
rules = ObservationRules(preset)

def rollout(env, a, obs_after=None):
    sim = copy.deepcopy(env)
    total = 0.0
    obs, r, term, trunc, info = sim.step(a)
    total += r
    if info.get("crashed", False) or term:
        return -1000.0
    for k in range(H - 1):
        obs, r, term, trunc, info = sim.step(int(rules.actions(obs[None])[0]))
        total += r
        if term and info.get("crashed", False):
            return -1000.0 + k
        if term or trunc:
            break
    return total

for seed in seeds:
    env = make_env(preset)
    obs, _ = env.reset(seed=seed)
    ret, t0, steps, speeds, lcs = 0.0, time.time(), 0, [], 0
    while True:
        base = int(rules.actions(obs[None])[0])
        if H == 0:
            a = base
        else:
            scores = [rollout(env, a) for a in range(5)]
            best = max(scores)
            a = base if scores[base] >= best - 1e-9 else int(np.argmax(scores))
        obs, r, term, trunc, info = env.step(a)
        ret += r; steps += 1; speeds.append(env.unwrapped.vehicle.speed); lcs += a in (0, 2)
        if term or trunc:
            break
    print(f"seed {seed} H {H}: return {ret:.2f} steps {steps} crashed {info.get('crashed')} speed {np.mean(speeds):.2f} lc-actions {lcs} time {time.time()-t0:.0f}s", flush=True)
