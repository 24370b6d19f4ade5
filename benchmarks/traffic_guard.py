"""What `KeepTraffic` (zodrive/envs/traffic.py) costs per environment step, measured side by side.

The same highway-env environment is stepped with and without the wrapper, in alternating rounds of
the same actions from the same seeds, so that machine load falls on both alike. Ends with one line:
guard_overhead=<percent of a step's wall time>
"""

from __future__ import annotations

import argparse
import time

from zodrive.envs import load_preset, make_env


def rate(env, steps: int, seed: int) -> float:
    """Steps per second of IDLE decisions from `seed` (an ended episode restarts from the next seed)."""
    env.reset(seed=seed)
    t0 = time.perf_counter()
    for _ in range(steps):
        _, _, term, trunc, _ = env.step(1)
        if term or trunc:
            seed += 1
            env.reset(seed=seed)
    return steps / (time.perf_counter() - t0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="highway-fast")
    parser.add_argument("--steps", type=int, default=300, help="steps per round")
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    import torch

    torch.set_num_threads(1)
    guarded = make_env(load_preset(args.preset))
    bare = guarded.env  # the same env without KeepTraffic
    with_guard, without = [], []
    for r in range(args.rounds):
        with_guard.append(rate(guarded, args.steps, 1000 * r))
        without.append(rate(bare, args.steps, 1000 * r))
    a, b = sorted(with_guard)[len(with_guard) // 2], sorted(without)[len(without) // 2]
    print(f"{args.preset} env steps/s, median of {args.rounds} rounds of {args.steps}: "
          f"with KeepTraffic {a:.1f}, without {b:.1f}")
    print(f"guard_overhead={100 * (b / a - 1):.2f}")


if __name__ == "__main__":
    main()
