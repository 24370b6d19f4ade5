"""What the discrete preset shows of the ego's own speed: `baseline:rules` drives three tuning
seeds and each step's true speed (the simulator's) is printed beside the observed one (vx of the
ego row times the preset's vx range). Usage: python studies/planner/speed_seen.py"""
import numpy as np

from zodrive.drivers.rules import ObservationRules
from zodrive.envs.presets import load_preset, make_env

preset = load_preset("discrete")
vx_range = preset["highway"]["observation"]["features_range"]["vx"][1]
rules = ObservationRules(preset)
true, seen = [], []
for seed in (50000, 50001, 50002):
    env = make_env(preset)
    obs, _ = env.reset(seed=seed)
    done = False
    while not done:
        obs, _, terminated, truncated, _ = env.step(int(rules.actions(obs[None])[0]))
        true.append(env.unwrapped.vehicle.speed)
        seen.append(obs[0, 3] * vx_range)
        done = terminated or truncated
true, seen = np.array(true), np.array(seen)
print(f"{len(true)} steps; true speed {true.min():.2f}-{true.max():.2f} m/s (mean {true.mean():.2f}); "
      f"observed {seen.min():.2f}-{seen.max():.2f} m/s")
for low, high in [(20, 22.5), (22.5, 25), (25, 27.5), (27.5, 30.01)]:
    band = (true >= low) & (true < high)
    if band.any():
        print(f"  true {low}-{high} m/s: {band.mean():.1%} of steps, observed {seen[band].min():.2f}-{seen[band].max():.2f} m/s")
