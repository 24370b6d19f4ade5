"""Which noise (smooth@SIGMA) and window (temporal@K) to bench: clean cost and robustness on tuning seeds.

For the zoo's highway-fast DQN (seed 0), each defense clean on 30 tuning episodes (seeds 50000+, never the
bench's) and under random search at eps 0.05 with version 4's cap (500 queries a step) on the first 10,
beside the undefended policy; and how often the defense changes the policy's clean action.

    python studies/defenses-field/tune.py --out studies/defenses-field/runs
"""

from __future__ import annotations

import argparse
import json
import subprocess
from pathlib import Path

MODEL = "models/zoo/highway-fast-dqn/seed-0"
DEFENSES = ("none", "smooth@0.02", "smooth@0.05", "smooth@0.1", "temporal@3")


def run(defense: str, attacked: bool, episodes: int, out: Path) -> dict:
    folder = out / f"{defense}-{'rs0.05' if attacked else 'clean'}"
    if not (folder / "summary.json").exists():
        cmd = ["zodrive", "evaluate", MODEL, "--preset", "highway-fast", "--episodes", str(episodes), "--seed", "50000",
               "--out", str(folder), "--no-progress"]
        cmd += [] if defense == "none" else ["--defense", defense]
        cmd += ["--attack", "random-search", "--eps", "0.05", "--query-budget", "500"] if attacked else []
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return json.loads((folder / "summary.json").read_text())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("studies/defenses-field/runs"))
    parser.add_argument("--defenses", nargs="*", default=list(DEFENSES))
    args = parser.parse_args()
    for defense in args.defenses:
        clean = run(defense, False, 30, args.out)
        hit = run(defense, True, 10, args.out)
        print(f"{defense:12s} clean {clean['mean_return']:6.2f} ({100 * clean['collision_rate']:3.0f}%, "
              f"{clean['mean_speed']:.1f} m/s, {clean.get('lane_changes_per_episode', 0):.1f} lane changes)  "
              f"| rs eps 0.05: {hit['mean_return']:6.2f} ({100 * hit['collision_rate']:3.0f}%), success "
              f"{100 * (hit.get('attack_success_rate') or 0):.0f}%, {hit.get('queries_per_step', 0):.0f} q/step",
              flush=True)


if __name__ == "__main__":
    main()
