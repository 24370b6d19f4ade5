"""highway-env's closest-lane search against zodrive's FastLaneNetwork (`--search lanes`), or its neighbour
search against FastNeighbourRoad (`--search neighbours`), in one run.

Per scenario, the same episodes (same seeds, same actions) are stepped with each search in turn,
interleaved episode by episode so that load on the machine hits both alike; the trajectories must be
identical. Prints the environment steps/s of each and ends with one line per scenario:
<scenario> stock=<steps/s> fast=<steps/s> speedup=<x>

What committed runs printed: logs lane_search.txt and (--search neighbours) neighbour_search.txt in
results/benchmarks.txt (docs/speed.md says which run each is; `zodrive pack --logs --unpack results/benchmarks`
gives them back as results/benchmarks/NAME.txt). To keep a new run's:

    python benchmarks/lane_search.py [options] > results/benchmarks/NAME.txt
    zodrive pack --logs results/benchmarks   # folds it in (a log of the same name is replaced)
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import zodrive.envs.highway as zodrive_envs
from zodrive.envs import load_preset, make_env

SWITCHES = {"lanes": "use_fast_lanes", "neighbours": "use_fast_neighbours"}  # --search -> what zodrive's envs call


def episode(preset: str, seed: int, fast: bool, search: str) -> tuple[list[np.ndarray], float, int]:
    """One episode of random actions; its observations, its stepping time and its steps."""
    switch = SWITCHES[search]
    real = getattr(zodrive_envs, switch)
    setattr(zodrive_envs, switch, real if fast else (lambda road_or_network: None))
    try:
        env = make_env(load_preset(preset))
        obs, _ = env.reset(seed=seed)
    finally:
        setattr(zodrive_envs, switch, real)
    env.action_space.seed(seed)
    trace, wall, steps = [obs], 0.0, 0
    while True:
        action = env.action_space.sample()
        start = time.perf_counter()
        obs, reward, terminated, truncated, _ = env.step(action)
        wall += time.perf_counter() - start
        steps += 1
        trace += [obs, np.array([reward])]
        if terminated or truncated:
            return trace, wall, steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", nargs="+", default=["intersection", "roundabout", "merge", "highway-fast"])
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=100000)
    parser.add_argument("--search", choices=sorted(SWITCHES), default="lanes")
    args = parser.parse_args()
    for preset in args.scenarios:
        wall = {True: 0.0, False: 0.0}
        steps = 0
        for seed in range(args.seed, args.seed + args.episodes):
            runs = {}
            for fast in (False, True):
                runs[fast], seconds, n = episode(preset, seed, fast, args.search)
                wall[fast] += seconds
            steps += n
            assert len(runs[True]) == len(runs[False]) and all(
                np.array_equal(a, b) for a, b in zip(runs[True], runs[False])), f"{preset} seed {seed} differs"
        stock, fast = steps / wall[False], steps / wall[True]
        print(f"{preset} stock={stock:.1f} fast={fast:.1f} speedup={fast / stock:.2f}  "
              f"({steps} identical steps, {args.episodes} episodes)", flush=True)


if __name__ == "__main__":
    main()
