"""One shielded episode of highway-fast step by step: actions, lanes, speeds, and at one step the true
and the seen rows with the shield's room test on each (issue 64's extra crashes, README section 4).

    python studies/defended-highway-fast/trap.py MODEL SEED [--attack random-search] [--step N]

MODEL behind `shield@0.05`, attacked at eps 0.05 with a 500-query budget per step (the bench's
ensemble members at its largest eps; `--attack pgd`: the white-box column, through the shield by BPDA;
`--attack none`: clean) on highway-fast, episode seed SEED, as
`zodrive evaluate` drives it (same attack seed). `--step N`: the step to print in full (default: the
last). A zoo DQN zip is read with stable-baselines3's loader (`--trust-model`); the imitation
drivers are read without it.
"""

from __future__ import annotations

import argparse
import inspect
from typing import Any

import gymnasium as gym
import numpy as np

from zodrive.defense.shield import Shield
from zodrive.drivers.rules import ObservationRules
from zodrive.envs import load_preset, scenario
from zodrive.evaluation.rollout import run_episode
from zodrive.system import make_policy_env, spec_for

EPS = 0.05
NAMES = ["LEFT", "IDLE", "RIGHT", "FASTER", "SLOWER"]


class Log(gym.Wrapper):
    """Innermost wrapper: what the car did at each step, the row it truly had and the one it saw."""

    def __init__(self, env: gym.Env, rows: list[dict[str, Any]]) -> None:
        super().__init__(env)
        self.rows = rows

    def reset(self, **kwargs: Any) -> Any:
        obs, info = self.env.reset(**kwargs)
        self.last = (obs, info)
        return obs, info

    def step(self, action: Any) -> Any:
        seen, info = self.last
        car = self.env.unwrapped.vehicle
        self.rows.append({"action": int(action), "seen": seen, "true": info.get("clean_obs", seen),
                          "speed": float(car.speed), "lane": int(car.lane_index[2])})
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.last = (obs, info)
        return obs, reward, terminated, truncated, info


def rooms_line(rules: ObservationRules, obs: np.ndarray) -> str:
    # `top` (the FASTER test's room) is v6's; the code of an earlier version (run with PYTHONPATH) has no such flag
    r = rules.rooms(obs[None], top=True) if "top" in inspect.signature(rules.rooms).parameters else rules.rooms(obs[None])
    keys = ("own", "own_top", "left", "right", "left_blocked", "right_blocked", "moving")
    return "  ".join(f"{k} {r[k][0]:.1f}" if r[k].dtype.kind == "f" else f"{k} {bool(r[k][0])}" for k in keys if k in r)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("model")
    parser.add_argument("seed", type=int)
    parser.add_argument("--attack", default="random-search")
    parser.add_argument("--step", type=int)
    args = parser.parse_args()
    preset = load_preset("highway-fast")
    options = {"eps": EPS} if args.attack == "pgd" else {"eps": EPS, "query_budget": 500}  # PGD: white-box, no queries
    spec = None if args.attack == "none" else spec_for(args.attack, scenario(preset), options)
    victim, env = make_policy_env(args.model, preset, spec, defense=f"shield@{EPS}", trust="highway-fast-dqn" in args.model)
    rows: list[dict[str, Any]] = []
    record = run_episode(Log(env, rows), victim, episode=0, seed=args.seed, max_return=None).to_dict()
    print(f"{args.model} + shield@{EPS}, {args.attack}, seed {args.seed}: return {record['return']:.2f}, "
          f"{record['length']} steps, crashed {record['crashed']}")
    print("actions:", " ".join(NAMES[r["action"]] for r in rows))
    print("lanes:  ", " ".join(str(r["lane"]) for r in rows))
    print("speeds: ", " ".join(f"{r['speed']:.1f}" for r in rows))
    step = len(rows) - 1 if args.step is None else args.step
    row = rows[step]
    shield, plain = Shield(preset, EPS), ObservationRules(preset)
    np.set_printoptions(precision=1, suppress=True, linewidth=120)
    print(f"step {step}: {NAMES[row['action']]} at {row['speed']:.1f} m/s in lane {row['lane']}; rows in m, m/s "
          "(presence, x, y, vx, vy; ego absolute, others relative)")
    print("true:\n", row["true"] * plain.scale)
    print("seen:\n", row["seen"] * plain.scale)
    print(f"shield's test on the seen rows (eps {EPS}): {rooms_line(shield.rules, row['seen'])}")
    print(f"plain test on the true rows (eps 0):     {rooms_line(plain, row['true'])}")


if __name__ == "__main__":
    main()
