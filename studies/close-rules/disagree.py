"""Replay a student on evaluation seeds and list where it and baseline:close-rules disagree (the last 8).
Usage: python studies/close-rules/disagree.py MODEL SEED ..."""
import sys, numpy as np
from zodrive.envs import load_preset, make_env
from zodrive.policies.resolve import load_victim
from zodrive.drivers.rules import named_rules
preset = load_preset("discrete")
student = load_victim(sys.argv[1], preset)
teacher = named_rules(preset, "close-rules")
names = ["LANE_LEFT", "IDLE", "LANE_RIGHT", "FASTER", "SLOWER"]
for seed in map(int, sys.argv[2:]):
    env = make_env(preset); obs, _ = env.reset(seed=seed); done = False; t = 0; dis = []
    while not done:
        a = int(student.actions(student.query(obs[None].astype(np.float32)))[0]); b = int(teacher.actions(obs[None])[0])
        if a != b: dis.append((t, names[a], names[b]))
        obs, r, te, tr, _ = env.step(a); done = te or tr; t += 1
    print(seed, "steps", t, "crashed", env.unwrapped.vehicle.crashed, "disagreements (step, student, teacher):", dis[-8:], len(dis))
