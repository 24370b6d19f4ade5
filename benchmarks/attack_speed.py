"""Attack speed on the shipped DQN, measured side by side in one run.

1. Per environment step, ZO-SignSGD at T iterations and q directions (early stopping off,
   so both do all T iterations): Algorithm 1 done literally - one victim query per call,
   q + 1 calls per iteration - against zodrive's engine - one batched call per iteration.
2. Per environment step on the *same states*: a clean rollout records its observations and
   times each step (environment step + the policy's decision); then the default attack
   (T = 100, q = 20, early stopping on) and the query-saving one (`--warm-start --patience
   10`) attack exactly those observations in order (episode boundaries kept, so warm starts
   carry as in an evaluation). Attacked cost per step = the recorded step + the attack; a
   crash cannot shorten anything, since both sides see the same steps.

Ends with one line: speedup_vs_naive=<x> attacked_over_clean_per_step=<y> saving_over_clean_per_step=<z>
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
from zodrive.evaluation.rollout import clean_states

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


def same_states(model: str, episodes: int, max_steps: int, seed: int = SEED) -> dict[str, tuple[float, float, float]]:
    """{config: (ms per step, queries per step, success on applicable steps)} on one clean
    trajectory's states; `clean` is the environment step plus the policy's decision."""
    preset = load_preset("discrete", [f"max_episode_steps={max_steps}"])
    victim = sb3_victim(load_model(model, preset))
    env = make_env(preset)
    states, starts, step_time = [], [], 0.0
    for i in range(episodes):
        obs, _ = env.reset(seed=seed + i)
        starts.append(len(states))
        done = False
        while not done:
            states.append(obs)
            t0 = time.perf_counter()
            action = int(victim.query(obs[None]).argmax())
            obs, _, terminated, truncated, _ = env.step(action)
            step_time += time.perf_counter() - t0
            done = terminated or truncated
    clean = step_time / len(states)
    results = {"clean": (1000 * clean, 1.0, float("nan"))}
    default = load_attack("zo-signsgd")
    for name, spec in {"default": default,
                       "warm-start+patience": default.with_overrides(warm_start=True, patience=10)}.items():
        attack, objective, oracle = spec.build(victim, **attack_context(preset))
        spent, queries, hits, applicable = 0.0, 0, 0, 0
        for k, obs in enumerate(states):
            if k in starts:
                attack.begin_episode()
                oracle.begin_episode()
            t0 = time.perf_counter()
            result = attack.perturb(obs[None], oracle, objective)
            spent += time.perf_counter() - t0
            queries += int(result.queries[0])
            hits += int(result.success[0])
            applicable += int(not result.already[0])
        results[name] = (1000 * (clean + spent / len(states)), queries / len(states), hits / max(applicable, 1))
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="models/dqn")
    parser.add_argument("--states", type=int, default=5, help="environment steps timed per method")
    parser.add_argument("--steps", type=int, default=100, help="T")
    parser.add_argument("--n-directions", type=int, default=20, help="q")
    parser.add_argument("--episodes", type=int, default=3, help="clean episodes whose states are attacked")
    parser.add_argument("--max-steps", type=int, default=150, help="steps per clean episode at most")
    parser.add_argument("--seed", type=int, default=SEED, help="first clean episode's seed (default: tuning seeds)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    naive, batched = per_step(args.model, args.states, args.steps, args.n_directions)
    print(f"per environment step, T={args.steps}, q={args.n_directions}, all iterations:")
    print(f"  literal Algorithm 1 (1 query per call): {1000 * naive:8.1f} ms")
    print(f"  zodrive engine (1 call per iteration):  {1000 * batched:8.1f} ms")
    results = same_states(args.model, args.episodes, args.max_steps, args.seed)
    clean = results["clean"][0]
    print(f"per environment step on the same states ({args.episodes} clean episodes of at most {args.max_steps} "
          f"steps, seeds {args.seed}..{args.seed + args.episodes - 1}):")
    for name, (ms, queries, success) in results.items():
        print(f"  {name:20s} {ms:8.2f} ms/step, {queries:7.1f} queries/step, success {success:.1%}, "
              f"x{ms / clean:.2f} of clean")
    print(f"speedup_vs_naive={naive / batched:.1f} attacked_over_clean_per_step={results['default'][0] / clean:.2f} "
          f"saving_over_clean_per_step={results['warm-start+patience'][0] / clean:.2f}")


if __name__ == "__main__":
    main()
