"""Is intersection's bar out of reach of its observation? A look-ahead planner blind to the routes.

`baseline:planner` beats always-IDLE on intersection by reading the simulator, including where each
car will turn, which the (15, 7) observation does not show (`observe_intentions` is off). This
planner reads the simulator too, but guesses what the observation cannot tell: in each of
`samples` copies, every car that has not yet entered the junction gets a route drawn uniformly
among the three exits other than its own entry, and the copy's random stream (future spawns) is
drawn anew. Each meta-action is taken in every copy and IDLE held for `horizon_s` seconds; an
action scores the mean summed reward of its copies (highway-env's own reward: -5 a crash, which
ends the copy, 1 a step at 9 m/s, 1 on arrival); the same copies serve every action, and IDLE
wins ties. So it chooses by expected return over the routes and spawns the observation leaves
unknown: roughly what a policy of the observation could reach. Roughly, because it still reads what
else the simulator holds (each driver's IDM parameters, cars beyond the 15 observed), draws routes
uniformly rather than from what the observation implies, and looks 5 s ahead with 8 samples.

Scored on tuning seeds 60000-60029 (`yield_rules.py`'s) by default, beside always-IDLE and the planner.

Run: python studies/intersection-rule/route_blind_planner.py [--samples 8] [--episodes 30] [--seed 60000]
"""

from __future__ import annotations

import argparse
import copy
import time
from typing import Any

import numpy as np

import zodrive
from zodrive.envs import load_preset
from zodrive.envs.presets import make_env
from zodrive.evaluation.stats import paired_difference_ci

IDLE = 1
SEED = 60_000


class RouteBlindPlanner:
    """Expected-return look-ahead over `samples` guesses of the routes the observation hides."""

    def __init__(self, env: Any, samples: int, horizon_s: float = 5.0) -> None:
        self.env, self.samples = env, samples
        self.steps = max(1, round(horizon_s * env.unwrapped.config["policy_frequency"]))
        self.calls = 0

    def __call__(self) -> int:
        base = self.env.unwrapped
        self.calls += 1
        actions = [int(a) for a in base.action_type.get_available_actions()]
        copies = [self._guess(base, 1000 * self.calls + k) for k in range(self.samples)]
        scores = {a: np.mean([self._rollout(copy.deepcopy(c), a) for c in copies]) for a in actions}
        best = max(scores.values())
        return IDLE if scores.get(IDLE, -np.inf) >= best else max(scores, key=lambda a: scores[a])

    @staticmethod
    def _guess(base: Any, seed: int) -> Any:
        sim = copy.deepcopy(base)
        rng = np.random.default_rng(seed)
        sim.np_random = rng
        sim.road.np_random = rng
        for v in sim.road.vehicles:
            if v is sim.vehicle or getattr(v, "route", None) is None or not v.lane_index[0].startswith("o"):
                continue
            entry = int(v.lane_index[0][1:])
            v.plan_route_to(f"o{rng.choice([d for d in range(4) if d != entry])}")
            if v.target_lane_index[0] != v.lane_index[0]:  # already steering for its (true) turn: redraw that too
                v.target_lane_index = (*v.route[1][:2], 0)
                v.route = v.route[1:]
        return sim

    def _rollout(self, sim: Any, action: int) -> float:
        total = 0.0
        for _ in range(self.steps):
            _, reward, terminated, truncated, _ = sim.step(action)
            total += float(reward)
            if terminated or truncated:
                break
            action = IDLE
        return total


def drive(seed: int, samples: int) -> dict[str, Any]:
    env = make_env(load_preset("intersection"))
    env.reset(seed=seed)
    planner = RouteBlindPlanner(env, samples)
    total, crashed, steps, speeds = 0.0, False, 0, []
    while True:
        _, reward, terminated, truncated, info = env.step(planner())
        total, steps = total + float(reward), steps + 1
        speeds.append(env.unwrapped.vehicle.speed)
        crashed = crashed or bool(info.get("crashed", False))
        if terminated or truncated:
            return {"return": total, "crashed": crashed, "steps": steps, "speed": float(np.mean(speeds))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=8)
    parser.add_argument("--episodes", type=int, default=30)
    parser.add_argument("--seed", type=int, default=SEED, help="the first tuning seed")
    args = parser.parse_args()
    start = time.perf_counter()
    blind = [drive(args.seed + i, args.samples) for i in range(args.episodes)]
    seconds = time.perf_counter() - start
    print(f"| Policy | Return | Collisions | Speed (m/s) | Δ always-IDLE (paired 95% CI) |\n|---|---|---|---|---|")
    idle = [e["return"] for e in zodrive.evaluate("baseline:idle", "intersection", episodes=args.episodes, seed=args.seed).episodes]
    rows = [(f"route-blind planner, {args.samples} samples", [e["return"] for e in blind],
             np.mean([e["crashed"] for e in blind]), np.mean([e["speed"] for e in blind]))]
    for name in ("baseline:idle", "baseline:planner"):
        r = zodrive.evaluate(name, "intersection", episodes=args.episodes, seed=args.seed)
        rows.append((name, [e["return"] for e in r.episodes], r.summary["collision_rate"], r.summary["mean_speed"]))
    for label, returns, crashes, speed in rows:
        mean, low, high = paired_difference_ci(returns, idle)
        print(f"| {label} | {np.mean(returns):.2f} | {100 * crashes:.0f} % | {speed:.1f} | {mean:+.2f} ({low:+.2f} to {high:+.2f}) |")
    print(f"route-blind planner: {seconds:.0f} s for {args.episodes} episodes")


if __name__ == "__main__":
    main()
