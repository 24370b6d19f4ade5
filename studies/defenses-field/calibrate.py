"""How far does a clean observation depart from the one-step constant-velocity prediction of the last one?

The anomaly detector (`--defense detect`) fires where a row departs further than physics as observed allows.
This measures it on tuning seeds (50000+) of a scenario, with the zoo's DQN driving and one decision in five
random (so lane changes and braking are in the sample): per feature, the largest departure and the
99.9th percentile, for the other vehicles (matched by `tracks.match`) and for the ego row.

    python studies/defenses-field/calibrate.py --scenario highway-fast --episodes 60
"""

from __future__ import annotations

import argparse

import numpy as np

from zodrive.defense import tracks
from zodrive.envs import load_preset, make_env, scenario
from zodrive.policies.policy import resolve

MODELS = {"highway-fast": "models/zoo/highway-fast-dqn/seed-0", "merge": "models/zoo/merge-dqn/seed-0"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="highway-fast", choices=list(MODELS))
    parser.add_argument("--episodes", type=int, default=60)
    args = parser.parse_args()
    preset = load_preset(args.scenario)
    where = scenario(preset)
    r = where.feature_ranges
    kx = r["vx"][1] / r["x"][1] / where.policy_frequency
    ky = r["vy"][1] / r["y"][1] / where.policy_frequency
    victim = resolve(MODELS[args.scenario]).victim(preset)
    env, rng = make_env(preset), np.random.default_rng(0)
    others: list[np.ndarray] = []
    ego: list[np.ndarray] = []
    for episode in range(args.episodes):
        obs, _ = env.reset(seed=50000 + episode)
        done = False
        while not done:
            action = int(victim.actions(victim.query(obs[None]))[0]) if rng.random() > 0.2 else int(rng.integers(5))
            new, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
            if terminated and info.get("crashed"):
                break  # a crash is no sensor reading to learn from
            pred = tracks.advance(obs, 1, kx, ky, where.relative)
            pairs = tracks.match(new[None], pred, 0.2)[0]
            for i, j in enumerate(pairs):
                if j >= 0:
                    others.append(np.abs(new[1 + i, 1:5] - pred[1 + j, 1:5]))
            ego.append(np.abs(new[0, 1:5] - pred[0, 1:5]))
            obs = new
    for name, rows in (("others", np.array(others)), ("ego", np.array(ego))):
        print(f"{args.scenario} {name} ({len(rows)} rows): max " + ", ".join(
            f"{f} {v:.4f}" for f, v in zip(("x", "y", "vx", "vy"), rows.max(axis=0))) + " | p99.9 " + ", ".join(
            f"{f} {v:.4f}" for f, v in zip(("x", "y", "vx", "vy"), np.percentile(rows, 99.9, axis=0)))
            + " | p99 " + ", ".join(f"{f} {v:.4f}" for f, v in zip(("x", "y", "vx", "vy"), np.percentile(rows, 99, axis=0)))
            + " | p90 " + ", ".join(f"{f} {v:.4f}" for f, v in zip(("x", "y", "vx", "vy"), np.percentile(rows, 90, axis=0)))
            + " | share of rows with a departure above 0.05 in x or vx: "
            + f"{np.mean((rows[:, 0] > 0.05) | (rows[:, 2] > 0.05)):.3f}")


if __name__ == "__main__":
    main()
