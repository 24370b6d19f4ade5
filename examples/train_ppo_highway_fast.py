"""Train a PPO on highway-env's `highway-fast-v0` with plain stable-baselines3 (no zodrive).

This is the model a researcher brings: made by SB3 alone, saved with `model.save`. zodrive
then attacks it (`zodrive evaluate OUT/model.zip --preset highway-fast --attack random-search`).
Hyperparameters follow highway-env's own PPO example (two 256-unit layers, gamma 0.8,
learning rate 5e-4, 10 epochs of batch 64), on one environment so that it runs on one core.

Run: python examples/train_ppo_highway_fast.py --steps 100000 --seed 0 --out models/ppo-highway-fast
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import gymnasium as gym
import highway_env  # noqa: F401  (registers highway-fast-v0)
from stable_baselines3 import PPO
from stable_baselines3.common.monitor import Monitor


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=100_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    env = Monitor(gym.make("highway-fast-v0"), str(args.out / "monitor"))
    model = PPO("MlpPolicy", env, policy_kwargs=dict(net_arch=dict(pi=[256, 256], vf=[256, 256])),
                n_steps=512, batch_size=64, n_epochs=10, learning_rate=5e-4, gamma=0.8,
                seed=args.seed, device="cpu", verbose=0)
    start = time.perf_counter()
    model.learn(total_timesteps=args.steps)
    model.save(args.out / "model")
    (args.out / "train.json").write_text(json.dumps(
        {"script": "examples/train_ppo_highway_fast.py", "env_id": "highway-fast-v0", "steps": args.steps,
         "seed": args.seed, "wall_time_s": round(time.perf_counter() - start, 1)}, indent=2) + "\n")
    print(f"saved {args.out / 'model.zip'}")


if __name__ == "__main__":
    main()
