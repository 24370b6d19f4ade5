"""Attack speed on the shipped DQN, measured side by side in one run.

1. Per environment step, ZO-SignSGD at T iterations and q directions (early stopping off,
   so both do all T iterations): Algorithm 1 done literally - one victim query per call,
   q + 1 calls per iteration - against zodrive's engine - one batched call per iteration.
2. Per environment step on the *same states*: clean rollouts record their observations and
   time each step (environment step + the policy's decision); then the default attack
   (T = 100, q = 20, early stopping, warm start, patience 10) and the same searching every
   step from scratch until success or T (`--no-warm-start --no-patience`, the default
   until 2026-11-23) attack exactly those observations in order, through the evaluation's own lockstep
   loop (`run_lockstep` over environments that replay the recorded episodes; episode
   boundaries kept, so warm starts carry as in an evaluation), with 1, 8 and 32 episodes
   side by side. Attacked cost per step = the recorded step + the attack's time per step; a
   crash cannot shorten anything, since every side sees the same steps.

Ends with one line: speedup_vs_naive=<x> attacked_over_clean_per_step=<y> from_scratch_over_clean_per_step=<z>
lockstep_speedup=<w> (the default attack's time per step, one episode at a time over 8 side by side)

What committed runs printed: logs attack_speed*.txt in results/benchmarks.txt (docs/speed.md says which run each
is; `zodrive pack --logs --unpack results/benchmarks` gives them back as results/benchmarks/NAME.txt). To keep a
new run's:

    python benchmarks/attack_speed.py [options] > results/benchmarks/NAME.txt
    zodrive pack --logs results/benchmarks   # folds it in (a log of the same name is replaced)
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from zodrive.policies.policy import resolve
from zodrive.attacks.spec import AttackSpec, load_attack
from zodrive.envs import attack_context, load_preset, make_env
from zodrive.evaluation.evaluate import DEFAULT_ENVS
from zodrive.evaluation.rollout import clean_states, run_lockstep

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


def per_step(model: str, states: int, steps: int, q: int,
             envs: list[int]) -> tuple[float, dict[int, float], dict[int, float]]:
    """Per environment step [s]: literal Algorithm 1 on `states` states; the engine on
    max(envs) states attacked `n` at a time (rows of one call, as in lockstep) for each n; and
    the victim's forward passes alone for those queries in batches of n (q + 1) rows."""
    preset = load_preset("discrete")
    victim = resolve(model).victim(preset)  # any victim the CLI takes, read safely
    xs = clean_states(make_env(preset), victim, SEED, max(states, *envs))
    spec = AttackSpec(steps=steps, n_directions=q, early_stop=False)
    attack, objective, oracle = spec.build(victim, **attack_context(preset))
    mask = attack.threat.mask((5, 5))
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    for x in xs[:states]:
        literal_algorithm1(x, victim, objective, mask, steps=steps, q=q, mu=spec.mu,
                           step_size=spec.step_size, eps=spec.eps, rng=rng)
    naive = (time.perf_counter() - t0) / states
    engine = {}
    for n in envs:
        count = len(xs) // n * n
        attack.perturb(xs[:n], oracle, objective)  # untimed: the oracle's one-off calibration (`stable_batch`)
        t0 = time.perf_counter()
        for i in range(0, count, n):
            attack.perturb(xs[i:i + n], oracle, objective)
        engine[n] = (time.perf_counter() - t0) / count
    forward = {}  # the arithmetic alone: the forward passes of a step's T (q + 1) queries, nothing else
    for n in envs:
        batch = np.resize(xs, (n * (q + 1), *xs.shape[1:]))
        t0 = time.perf_counter()
        for _ in range(steps):
            victim.query(batch)
        forward[n] = (time.perf_counter() - t0) / n
    return naive, engine, forward


class Replay(gym.Env):
    """Replays recorded clean episodes whatever the policy does: `reset(seed=s)` starts the
    episode recorded from seed s. Attacks then see exactly the clean states, in order."""

    def __init__(self, episodes: dict[int, np.ndarray], action_space: gym.Space) -> None:
        self.episodes, self.action_space = episodes, action_space
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, next(iter(episodes.values())).shape[1:], np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None):  # type: ignore[override]
        self.states, self.t = self.episodes[seed], 0
        return self.states[0], {}

    def step(self, action):  # type: ignore[override]
        self.t += 1
        return self.states[min(self.t, len(self.states) - 1)], 0.0, self.t >= len(self.states), False, {}


def clean_episodes(model: str, episodes: int, max_steps: int, seed: int) -> tuple[dict[int, np.ndarray], float, Any]:
    """The states of `episodes` clean episodes (by seed), the time of a clean step
    (environment step + the policy's decision) [s], and the victim."""
    preset = load_preset("discrete", [f"max_episode_steps={max_steps}"])
    victim = resolve(model).victim(preset)  # any victim the CLI takes, read safely
    env = make_env(preset)
    recorded, step_time, count = {}, 0.0, 0
    for i in range(episodes):
        obs, _ = env.reset(seed=seed + i)
        states, done = [], False
        while not done:
            states.append(obs)
            t0 = time.perf_counter()
            action = int(victim.query(obs[None]).argmax())
            obs, _, terminated, truncated, _ = env.step(action)
            step_time += time.perf_counter() - t0
            done = terminated or truncated
        recorded[seed + i] = np.stack(states)
        count += len(states)
    return recorded, step_time / count, (victim, preset, env.action_space)


def same_states(recorded: dict[int, np.ndarray], victim_of: Any, spec: AttackSpec, envs: int) -> tuple[float, float, float]:
    """(attack time per step [s], queries per step, success on applicable steps) of `spec`
    on the recorded states, `envs` episodes side by side as `zodrive evaluate --envs` runs
    them (episode boundaries kept, so warm starts carry as in an evaluation)."""
    victim, preset, space = victim_of
    steps: list[dict[str, Any]] = []
    attacker = spec.build(victim, **attack_context(preset))
    replays = [Replay(recorded, space) for _ in range(envs)]
    for _ in run_lockstep(replays, victim, [(i, s) for i, s in enumerate(recorded)], max_return=None,
                          attacker=attacker, on_step=steps.append):
        pass
    applicable = sum(not s["already"] for s in steps)
    return (sum(s["wall_time"] for s in steps) / len(steps), sum(s["queries"] for s in steps) / len(steps),
            sum(s["success"] for s in steps) / max(applicable, 1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="models/dqn", help="any policy the CLI takes (a discrete preset one)")
    parser.add_argument("--states", type=int, default=5, help="environment steps timed per method")
    parser.add_argument("--steps", type=int, default=100, help="T")
    parser.add_argument("--n-directions", type=int, default=20, help="q")
    parser.add_argument("--episodes", type=int, default=3, help="clean episodes whose states are attacked")
    parser.add_argument("--max-steps", type=int, default=150, help="steps per clean episode at most")
    parser.add_argument("--seed", type=int, default=SEED, help="first clean episode's seed (default: tuning seeds)")
    parser.add_argument("--envs", type=int, nargs="+", default=[1, DEFAULT_ENVS, 32],
                        help="episodes side by side (the first is the reference of lockstep_speedup)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    naive, engine, forward = per_step(args.model, args.states, args.steps, args.n_directions, args.envs)
    print(f"per environment step, T={args.steps}, q={args.n_directions}, all iterations:")
    print(f"  literal Algorithm 1 (1 query per call):   {1000 * naive:8.2f} ms")
    for n, cost in engine.items():
        print(f"  zodrive engine, {n:2d} steps per call:      {1000 * cost:8.2f} ms  (x{naive / cost:.1f}); "
              f"its forward passes alone {1000 * forward[n]:.2f} ms (x{naive / forward[n]:.1f}: the ceiling)")
    recorded, clean, victim_of = clean_episodes(args.model, args.episodes, args.max_steps, args.seed)
    print(f"per environment step on the same states ({args.episodes} clean episodes of at most {args.max_steps} "
          f"steps, seeds {args.seed}..{args.seed + args.episodes - 1}; clean step {1000 * clean:.2f} ms = "
          "environment step + decision):")
    default = load_attack("zo-signsgd")
    ratio: dict[tuple[str, int], float] = {}
    for name, spec in {"default": default,
                       "from-scratch": default.with_overrides(warm_start=False, clear=["patience"])}.items():
        for envs in args.envs:
            attack, queries, success = same_states(recorded, victim_of, spec, envs)
            ratio[name, envs] = (clean + attack) / clean
            print(f"  {name:20s} --envs {envs:<3d} attack {1000 * attack:6.2f} ms/step, {queries:6.1f} queries/step, "
                  f"success {success:.1%}, x{ratio[name, envs]:.2f} of clean")
    n1, nd = args.envs[0], DEFAULT_ENVS if DEFAULT_ENVS in args.envs else args.envs[-1]
    attack_ms = {envs: ratio["default", envs] - 1 for envs in args.envs}
    print(f"speedup_vs_naive={naive / engine[nd]:.1f} (--envs {nd}; {n1}: x{naive / engine[n1]:.1f}) "
          f"attacked_over_clean_per_step={ratio['default', nd]:.2f} (--envs {nd}) "
          f"from_scratch_over_clean_per_step={ratio['from-scratch', nd]:.2f} (--envs {nd}) "
          f"lockstep_speedup={attack_ms[n1] / attack_ms[nd]:.1f} (attack time, --envs {n1} over {nd}; "
          + ", ".join(f"{e}: x{attack_ms[n1] / attack_ms[e]:.1f}" for e in args.envs) + ")")

if __name__ == "__main__":
    main()
