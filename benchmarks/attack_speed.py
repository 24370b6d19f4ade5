"""Attack speed on the shipped DQN, measured side by side in one run.

1. Per environment step, ZO-SignSGD at T iterations and q directions (early stopping off,
   so both do all T iterations): Algorithm 1 done literally - one victim query per call,
   q + 1 calls per iteration - against zodrive's engine - one batched call per iteration.
2. A clean and attacked evaluations of the same episodes (same seeds): the default attack
   config (T = 100, q = 20, early stopping on) and the query-saving one (`--warm-start
   --patience 10`: start from the last step's perturbation, give up a stalled step); total
   wall time, return and queries per step of each.

Ends with one line: speedup_vs_naive=<x> attacked_over_clean=<y> saving_over_clean=<z>
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from zodrive.agents.loading import load_model
from zodrive.agents.victims import sb3_victim
from zodrive.attacks.spec import AttackSpec, load_attack
from zodrive.envs import attack_context, load_preset, make_env
from zodrive.evaluation.rollout import clean_states, run_episode
from zodrive.wrappers import make_attacked_env

from zodrive.seeds import TUNING_SEED as SEED  # tuning range, disjoint from evaluation seeds


def literal_algorithm1(x0: np.ndarray, victim, objective, mask: np.ndarray, *, steps: int, q: int,
                       mu: float, step_size: float, eps: float, rng: np.random.Generator) -> np.ndarray:
    """Algorithm 1 as printed: a Python loop, one query per function evaluation."""
    clean = victim.query(x0[None])

    def f(x: np.ndarray) -> float:
        out = torch.from_numpy(victim.query(x[None]))
        return float(objective.loss(out[:, None], torch.from_numpy(clean))[0, 0])

    x = x0.copy()
    d = int(mask.sum())
    for _ in range(steps):
        fx = f(x)
        g = np.zeros_like(x)
        for _ in range(q):
            u = rng.standard_normal(x.shape) * mask
            u /= np.linalg.norm(u)
            g += d * (f(x + mu * u) - fx) / mu * u
        x = np.clip(x0 + np.clip(x - step_size * np.sign(g) - x0, -eps, eps), -1, 1)
    return x


def per_step(model: str, states: int, steps: int, q: int) -> tuple[float, float]:
    preset = load_preset("discrete")
    victim = sb3_victim(load_model(model, preset))
    xs = clean_states(make_env(preset), victim, SEED, states)
    spec = AttackSpec(steps=steps, n_directions=q, early_stop=False)
    attack, objective, oracle = spec.build(victim, **attack_context(preset))
    mask = attack.threat.mask((5, 5))
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    for x in xs:
        literal_algorithm1(x, victim, objective, mask, steps=steps, q=q, mu=spec.mu,
                           step_size=spec.step_size, eps=spec.eps, rng=rng)
    naive = (time.perf_counter() - t0) / len(xs)
    t0 = time.perf_counter()
    for x in xs:
        attack.perturb(x[None], oracle, objective)
    batched = (time.perf_counter() - t0) / len(xs)
    return naive, batched


def evaluation(model: str, episodes: int) -> dict[str, tuple[float, int, float, float]]:
    """{config: (wall time [s], steps, mean return, queries per step)} on the same seeds."""
    preset = load_preset("discrete")
    victim = sb3_victim(load_model(model, preset))
    default = load_attack("zo-signsgd")
    configs = {"clean": None, "default": default,
               "warm-start+patience": default.with_overrides(warm_start=True, patience=10)}
    results = {}
    for name, spec in configs.items():
        env = make_attacked_env(preset, victim, spec)
        t0, n, returns, queries = time.perf_counter(), 0, [], 0
        for i in range(episodes):
            record = run_episode(env, victim, episode=i, seed=SEED + i, max_return=450.0)
            n, queries = n + record.length, queries + record.queries
            returns.append(record.return_)
        results[name] = (time.perf_counter() - t0, n, float(np.mean(returns)), queries / n)
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="models/dqn")
    parser.add_argument("--states", type=int, default=5, help="environment steps timed per method")
    parser.add_argument("--steps", type=int, default=100, help="T")
    parser.add_argument("--n-directions", type=int, default=20, help="q")
    parser.add_argument("--episodes", type=int, default=5)
    args = parser.parse_args()
    torch.set_num_threads(1)
    naive, batched = per_step(args.model, args.states, args.steps, args.n_directions)
    print(f"per environment step, T={args.steps}, q={args.n_directions}, all iterations:")
    print(f"  literal Algorithm 1 (1 query per call): {1000 * naive:8.1f} ms")
    print(f"  zodrive engine (1 call per iteration):  {1000 * batched:8.1f} ms")
    results = evaluation(args.model, args.episodes)
    clean = results["clean"][0]
    print(f"evaluation of {args.episodes} episodes (seeds {SEED}..{SEED + args.episodes - 1}):")
    for name, (wall, n, ret, queries) in results.items():
        print(f"  {name:20s} {wall:7.1f} s for {n:5d} steps ({1000 * wall / n:6.2f} ms/step), mean return "
              f"{ret:6.1f}, {queries:7.1f} queries/step, wall time x{wall / clean:.2f} of clean")
    print("  (attacked episodes end sooner when the agent crashes)")
    print(f"speedup_vs_naive={naive / batched:.1f} attacked_over_clean={results['default'][0] / clean:.2f} "
          f"saving_over_clean={results['warm-start+patience'][0] / clean:.2f}")

if __name__ == "__main__":
    main()
