"""Attack settings measured on states a model actually visits (tuning seeds, not eval seeds).

Collects observations from clean rollouts of MODEL on seeds 50,000+ (disjoint from the
evaluation seeds 100,000+), then attacks them all at once (batched across states) for each
setting, and prints success rate on applicable states, mean iterations, queries and L-inf.

    python studies/tune-attack/tune_attack.py models/dqn --grid loss=margin,paper step_size=0.01,0.02,0.05

What committed runs printed: log tune_attack.txt in results/benchmarks.txt (docs/design.md says which run each
is; `zodrive pack --logs --unpack results/benchmarks` gives them back as results/benchmarks/NAME.txt). To keep a
new run's:

    python studies/tune-attack/tune_attack.py MODEL --grid ... > results/benchmarks/NAME.txt
    zodrive pack --logs results/benchmarks   # folds it in (a log of the same name is replaced)
"""

from __future__ import annotations

import argparse
import itertools
import time

import numpy as np
import yaml

from zodrive.policies.loading import load_model
from zodrive.policies.victims import sb3_victim
from zodrive.attacks.spec import load_attack
from zodrive.cli import resolve_model_preset
from zodrive.envs import attack_context, make_env
from zodrive.evaluation.rollout import act

from zodrive.seeds import TUNING_SEED  # states come from seeds outside the evaluation range


def collect(model: str, episodes: int, every: int, seed: int = TUNING_SEED) -> tuple[np.ndarray, object, dict]:
    preset = resolve_model_preset(model, None, [])
    victim = sb3_victim(load_model(model, preset))
    env = make_env(preset)
    states = []
    for i in range(episodes):
        obs, _ = env.reset(seed=seed + i)
        done, t = False, 0
        while not done:
            if t % every == 0:
                states.append(obs)
            obs, _, term, trunc, _ = env.step(act(victim, obs))
            done, t = term or trunc, t + 1
    return np.stack(states), victim, preset


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model")
    parser.add_argument("--attack", default="zo-signsgd")
    parser.add_argument("--episodes", type=int, default=4)
    parser.add_argument("--every", type=int, default=5, help="keep every n-th state")
    parser.add_argument("--grid", nargs="*", default=[], metavar="KEY=V1,V2",
                        help="attack options to cross, e.g. attack=random-search,pgd eps=0.05,0.1 patience=null,10")
    parser.add_argument("--seed", type=int, default=TUNING_SEED,
                        help="first episode seed of the states (default: the tuning seeds; 100000 to check on evaluation seeds)")
    args = parser.parse_args()
    states, victim, preset = collect(args.model, args.episodes, args.every, args.seed)
    keys = [g.split("=")[0] for g in args.grid]
    values = [[yaml.safe_load(v) for v in g.split("=")[1].split(",")] for g in args.grid]
    print(f"{len(states)} states from {args.episodes} episodes (seeds {args.seed}+), attack {args.attack}")
    print("| " + " | ".join(keys + ["success", "already", "iterations", "queries/step",
                                    "median queries on success", "mean Linf", "ms/state"]) + " |")
    print("|" + "---|" * (len(keys) + 7))
    for combo in itertools.product(*values):
        spec = load_attack(args.attack, [f"{k}={v}" for k, v in zip(keys, combo)])
        attack, objective, oracle = spec.build(victim, **attack_context(preset))
        start = time.perf_counter()
        r = attack.perturb(states, oracle, objective)
        wall = time.perf_counter() - start
        ok = r.success[~r.already].mean() if (~r.already).any() else float("nan")
        won = r.queries[r.success]
        median = f"{np.median(won):.0f}" if won.size else "–"
        print("| " + " | ".join(str(v) for v in combo) +
              f" | {ok:.1%} | {r.already.mean():.1%} | {r.iterations.mean():.1f} | {r.queries.mean():.0f}"
              f" | {median} | {r.linf.mean():.3f} | {1000 * wall / len(states):.2f} |", flush=True)


if __name__ == "__main__":
    main()
