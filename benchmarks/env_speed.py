"""Stock highway-env Kinematics observation against zodrive's FastKinematics, in one run.

Measures environment steps/s on both presets, DQN and DDPG training steps/s, and the wall
time of an N-episode evaluation of the shipped DQN: stock with 2 workers, fast with 1 and
2 workers (the --workers speed-up), checking that stock and fast give identical returns.
Ends with one line: env_speedup=<x> train_speedup_dqn=<y> train_speedup_ddpg=<z>

What committed runs printed: log env_speed.txt in results/benchmarks.txt (docs/speed.md says which run each is;
`zodrive pack --logs --unpack results/benchmarks` gives them back as results/benchmarks/NAME.txt). To keep a new
run's:

    python benchmarks/env_speed.py > results/benchmarks/NAME.txt
    zodrive pack --logs results/benchmarks   # folds it in (a log of the same name is replaced)
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from zodrive.training.recipes import load_recipe, train
from zodrive.envs import load_preset, make_env
from zodrive.evaluation.evaluate import EvalJob, evaluate

TYPES = {"stock": "Kinematics", "fast": "FastKinematics"}


def env_rate(preset: str, kind: str, steps: int) -> float:
    env = make_env(load_preset(preset, [f"highway.observation.type={TYPES[kind]}"]))
    env.reset(seed=0)
    env.action_space.seed(0)
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    for _ in range(steps):
        action = 4 if preset == "discrete" else np.array([rng.uniform(-1, 1), 0.0], dtype=np.float32)
        _, _, term, trunc, _ = env.step(action)
        if term or trunc:
            env.reset()
    return steps / (time.perf_counter() - t0)


def train_rate(algo: str, kind: str, steps: int) -> float:
    recipe = load_recipe(algo, [f"total_timesteps={steps}", "checkpoint_every=0",
                                f"hyperparameters.learning_starts={steps // 4}"])
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        train(recipe, Path(tmp), progress_bar=False, preset_overrides=[f"highway.observation.type={TYPES[kind]}"])
        return steps / (time.perf_counter() - t0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env-steps", type=int, default=1500)
    parser.add_argument("--train-steps", type=int, default=2000)
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--model", default="models/dqn")
    args = parser.parse_args()
    import torch

    torch.set_num_threads(1)
    env_ratios = []
    for preset in ("discrete", "continuous"):
        stock, fast = env_rate(preset, "stock", args.env_steps), env_rate(preset, "fast", args.env_steps)
        env_ratios.append(fast / stock)
        print(f"env steps/s {preset:10s}: stock {stock:6.1f}  fast {fast:6.1f}  x{fast / stock:.2f}")
    train_ratios = {}
    for algo in ("dqn", "ddpg"):
        stock, fast = train_rate(algo, "stock", args.train_steps), train_rate(algo, "fast", args.train_steps)
        train_ratios[algo] = fast / stock
        print(f"train steps/s {algo:4s}: stock {stock:6.1f}  fast {fast:6.1f}  x{fast / stock:.2f}")
    if args.episodes:
        walls, returns = {}, {}
        for kind, workers in (("stock", 2), ("fast", 1), ("fast", 2)):
            preset = load_preset("discrete", [f"highway.observation.type={TYPES[kind]}"])
            job = EvalJob(model=str(Path(args.model) / "model.zip"), preset=preset)
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.perf_counter()
                summary = evaluate(job, args.episodes, Path(tmp), workers=workers, progress=False)
                walls[kind, workers] = time.perf_counter() - t0
                lines = (Path(tmp) / "episodes.jsonl").read_text().splitlines()
                returns[kind] = sorted((json.loads(x)["episode"], json.loads(x)["return"]) for x in lines)
            print(f"{args.episodes}-episode evaluation, {kind:5s} observation, --workers {workers}: "
                  f"{walls[kind, workers]:6.1f} s (mean return {summary['mean_return']:.2f})")
        print(f"--workers 2 speed-up (fast observation): x{walls['fast', 1] / walls['fast', 2]:.2f}")
        print(f"stock and fast observation give identical per-episode returns: {returns['stock'] == returns['fast']}")
    print(f"env_speedup={min(env_ratios):.2f} train_speedup_dqn={train_ratios['dqn']:.2f} "
          f"train_speedup_ddpg={train_ratios['ddpg']:.2f}")


if __name__ == "__main__":
    main()
