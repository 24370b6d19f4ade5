"""Attack speed on the shipped DQN, measured side by side in one run.

1. Per environment step, ZO-SignSGD at T iterations and q directions (early stopping off,
   so both do all T iterations): Algorithm 1 done literally - one victim query per call,
   q + 1 calls per iteration - against zodrive's engine - one batched call per iteration.
2. A clean and an attacked evaluation (default attack config: T = 100, q = 20, early
   stopping on) of the same episodes (same seeds): total wall time, and time per step.

Ends with one line: speedup_vs_naive=<x> attacked_over_clean=<y>
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


def evaluation(model: str, episodes: int) -> tuple[float, float, int, int]:
    preset = load_preset("discrete")
    victim = sb3_victim(load_model(model, preset))
    spec = load_attack("zo-signsgd")
    times, lengths = [], []
    for attacked in (False, True):
        env = make_attacked_env(preset, victim, spec if attacked else None)
        t0, n = time.perf_counter(), 0
        for i in range(episodes):
            n += run_episode(env, victim, episode=i, seed=SEED + i, max_return=450.0).length
        times.append(time.perf_counter() - t0)
        lengths.append(n)
    return times[0], times[1], lengths[0], lengths[1]


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
    clean, attacked, n_clean, n_att = evaluation(args.model, args.episodes)
    print(f"evaluation of {args.episodes} episodes (seeds {SEED}..{SEED + args.episodes - 1}):")
    print(f"  clean:    {clean:7.1f} s for {n_clean} steps ({1000 * clean / n_clean:.2f} ms/step)")
    print(f"  attacked: {attacked:7.1f} s for {n_att} steps ({1000 * attacked / n_att:.2f} ms/step; "
          "attacked episodes end sooner when the agent crashes)")
    print(f"  per-step cost ratio attacked/clean: {(attacked / n_att) / (clean / n_clean):.2f}")
    print(f"speedup_vs_naive={naive / batched:.1f} attacked_over_clean={attacked / clean:.2f}")


if __name__ == "__main__":
    main()
