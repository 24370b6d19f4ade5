"""How many queries does a black-box attack of the bench ensemble spend on a step it wins?

Protocol v4 caps the queries per step (issue 64, item 5). The cap is chosen here, on tuning seeds
(50000+, never the bench's 100000+): every step a capped attack still wins is one it won in at most
that many queries, so the share of won steps below a cap is what the cap keeps of the attack.

    python studies/query-cap/queries.py --episodes 10 --out studies/query-cap/runs
prints, per policy, attack and eps, the won steps' queries (median, 90th, 99th percentile, max) and
the share of won steps each candidate cap keeps; then the same over everything.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

POLICIES = {  # (model, scenario, extra flags)
    "highway-fast/dqn-seed-0": ("models/zoo/highway-fast-dqn/seed-0", "highway-fast", []),
    "highway-fast/ppo": ("models/ppo-highway-fast", "highway-fast", []),
    "highway-fast/imitation-seed-0": ("models/zoo/highway-fast-imitation/seed-0", "highway-fast", []),
    "merge/dqn-seed-0": ("models/zoo/merge-dqn/seed-0", "merge", []),
    "highway-fast/dqn-seed-0+shield@0.05": ("models/zoo/highway-fast-dqn/seed-0", "highway-fast",
                                            ["--defense", "shield@0.05"]),
}
ATTACKS = ("random-search", "zo-signsgd")
EPS = (0.01, 0.02, 0.05)
CAPS = (50, 100, 200, 300, 400, 500, 1000, 2002)


def run(name: str, attack: str, eps: float, episodes: int, seed: int, out: Path) -> Path:
    model, preset, extra = POLICIES[name]
    folder = out / name.replace("/", "__") / f"{attack}-eps{eps:g}"
    if not (folder / "summary.json").exists():
        cmd = ["zodrive", "evaluate", model, "--preset", preset, "--attack", attack, "--eps", str(eps),
               "--episodes", str(episodes), "--seed", str(seed), "--out", str(folder), "--no-progress", *extra]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return folder / "steps.jsonl"


def won(steps: Path) -> tuple[np.ndarray, int]:
    """Queries of the steps the attack won (not already won clean), and the number of attacked steps."""
    rows = [json.loads(line) for line in steps.read_text().splitlines() if line.strip()]
    attacked = [r for r in rows if not r["already"]]
    return np.array([r["queries"] for r in attacked if r["success"]], dtype=float), len(attacked)


def line(label: str, q: np.ndarray, n: int) -> str:
    if q.size == 0:
        return f"{label:58s} won 0 of {n} steps"
    keep = "  ".join(f"{c}:{(q <= c).mean():.3f}" for c in CAPS)
    return (f"{label:58s} won {q.size:5d} of {n:5d}; queries median {np.median(q):6.0f} p90 {np.percentile(q, 90):6.0f} "
            f"p99 {np.percentile(q, 99):6.0f} max {q.max():6.0f} | kept at cap {keep}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--seed", type=int, default=50000)
    parser.add_argument("--out", type=Path, default=Path("studies/query-cap/runs"))
    parser.add_argument("--policies", nargs="*", default=list(POLICIES))
    args = parser.parse_args()
    total: dict[str, list[np.ndarray]] = {a: [] for a in ATTACKS}
    counts = {a: 0 for a in ATTACKS}
    for name in args.policies:
        for attack in ATTACKS:
            for eps in EPS:
                q, n = won(run(name, attack, eps, args.episodes, args.seed, args.out))
                total[attack].append(q)
                counts[attack] += n
                print(line(f"{name} {attack} eps {eps:g}", q, n), flush=True)
    for attack in ATTACKS:
        print(line(f"ALL {attack}", np.concatenate(total[attack]), counts[attack]), flush=True)


if __name__ == "__main__":
    sys.exit(main())
