"""Can a rule that reads intersection's observation beat always-IDLE? Two yield rules, a small grid.

Both read the same (15, 7) observation as the zoo's DQNs (absolute x, y, vx, vy and heading, the
ego in row 0, its route fixed to o1) and issue SLOWER or FASTER:
- `arrival`: near the junction (ego within `near` m of its centre), yield while any moving car is
  inside the junction (`box` m) or will reach its centre within `window` s of the ego;
- `sweep`: yield when, moving on along its heading at >= 9 m/s for `horizon` s, with every other
  car at constant velocity, the ego would come within `dist` m of one.
Scored on tuning seeds 60000-60029, clear of the 50030-50129 that validate.py uses.

Run: python studies/intersection-rule/yield_rules.py
"""

from __future__ import annotations

import numpy as np

import zodrive

SLOWER, FASTER = 0, 2
SCALE = np.array([1, 100, 100, 20, 20, 1, 1.0])  # the preset's feature ranges: metres, m/s
SEED, EPISODES = 60_000, 30


def _rows(obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    o = np.asarray(obs, dtype=np.float64).reshape(15, 7) * SCALE
    return o[0], o[1:][o[1:, 0] > 0.5]


def arrival(window: float = 2.0, box: float = 10.0, near: float = 30.0, reach: float = 40.0):
    def decide(obs: np.ndarray) -> int:
        ego, others = _rows(obs)
        pe, ve, heading = ego[1:3], ego[3:5], ego[5:7]
        if np.dot(heading, -pe) <= 0:  # past the centre
            return FASTER
        for row in others:
            rel = row[1:3] - pe
            if np.linalg.norm(rel) < 12 and np.dot(rel, heading) > 0 and abs(heading[0] * rel[1] - heading[1] * rel[0]) < 2.5:
                return SLOWER  # a car right ahead in the ego's lane
        if np.linalg.norm(pe) > near:
            return FASTER
        te = max(np.linalg.norm(pe) - 5, 0) / max(np.linalg.norm(ve), 4.5)
        for row in others:
            p, v = row[1:3], row[3:5]
            d, s = np.linalg.norm(p), np.linalg.norm(v)
            if s > 0.5 and (d < box or (d < reach and np.dot(v, -p) > 0 and abs(d / s - te) < window)):
                return SLOWER
        return FASTER
    return decide


def sweep(horizon: float = 2.0, dist: float = 6.0):
    def decide(obs: np.ndarray) -> int:
        ego, others = _rows(obs)
        if not len(others):
            return FASTER
        t = np.linspace(0, horizon, int(horizon * 5) + 1)[:, None, None]
        pe = ego[1:3] + t * ego[5:7] * max(np.linalg.norm(ego[3:5]), 9.0)
        po = others[None, :, 1:3] + t * others[None, :, 3:5]
        return SLOWER if np.linalg.norm(po - pe, axis=-1).min() < dist else FASTER
    return decide


def main() -> None:
    grid = [("arrival", {}), ("arrival", {"window": 1.0}), ("arrival", {"window": 3.0}), ("arrival", {"near": 20.0}),
            ("arrival", {"box": 5.0}), ("sweep", {}), ("sweep", {"horizon": 3.0}), ("sweep", {"dist": 4.0}),
            ("sweep", {"horizon": 1.5, "dist": 5.0})]
    print("| Policy | Return | Collisions | Speed (m/s) | SLOWER share |\n|---|---|---|---|---|")
    for name, params in [("baseline:idle", None)] + grid:
        policy = name if params is None else {"arrival": arrival, "sweep": sweep}[name](**params)
        r = zodrive.evaluate(policy, "intersection", episodes=EPISODES, seed=SEED)
        counts = np.sum([e["action_counts"] for e in r.episodes], axis=0)
        label = name if params is None else f"{name} {params or '(defaults)'}"
        print(f"| {label} | {r.summary['mean_return']:.2f} | {100 * r.summary['collision_rate']:.0f} % | "
              f"{np.mean([e['mean_speed'] for e in r.episodes]):.1f} | {counts[0] / counts.sum():.0%} |")


if __name__ == "__main__":
    main()
