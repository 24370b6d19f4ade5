"""Issue 65's first must-show: every threat model on the same episodes of two drivers, and hsja on baseline:rules.

Runs every cell of the study, one process at a time, each a `zodrive evaluate` (or the one `zodrive
surrogate-train`) into studies/threat-models/runs/NAME. zodrive evaluate resumes a folder holding the
same evaluation, so running this again finishes what is missing and redoes nothing; a surrogate folder that
already holds surrogate.json is kept. Each command's printed output is appended to runs/NAME.log.

    OMP_NUM_THREADS=1 python studies/threat-models/run.py            # every cell
    OMP_NUM_THREADS=1 python studies/threat-models/run.py --list     # the commands, run nothing
    OMP_NUM_THREADS=1 python studies/threat-models/run.py NAME ...   # only these cells

Then `python studies/threat-models/table.py` prints the table (table.txt).
"""

from __future__ import annotations

import argparse
import os
import shlex
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
RUNS = HERE / "runs"
REL = RUNS.relative_to(ROOT)

# The two victims: the shipped driver on the paper's preset (CARD.md: preset `discrete`, evaluation
# seeds 100000+), and the highway-fast zoo's seed-0 DQN (needs --trust-model).
DRIVERS = {
    "dqn-driver": {
        "model": "models/dqn-driver",
        "flags": ["--preset", "discrete"],
        "episodes": 20,
        # The transfer attacker's own surrogate, fitted here (none was shipped for this victim).
        "surrogate": f"{REL}/surrogate-dqn-driver",
        "surrogate_flags": ["--episodes", "25", "--held-out", "5"],
    },
    "highway-fast": {
        "model": "models/zoo/highway-fast-dqn/seed-0",
        "flags": ["--preset", "highway-fast", "--trust-model"],
        "episodes": 50,
        # The surrogate of docs/attacks.md ("Transfer from a surrogate"), committed in results/.
        "surrogate": "results/transfer/surrogate",
    },
}
SEED = 100000
RULES_EPISODES = 50
EPSILONS = [0.05, 0.02]
BUDGET = ["--query-budget", "500"]

# The threat models of the table: (cell suffix, attack flags). ε is added per cell.
THREATS = [
    ("score", ["--attack", "zo-signsgd", *BUDGET]),
    ("decision", ["--attack", "hsja", "--access", "decision", *BUDGET]),
    ("one-object", ["--attack", "zo-signsgd", "--vehicles", "1", *BUDGET]),
    ("share-0.1", ["--attack", "zo-signsgd", "--attack-share", "0.1", *BUDGET]),
    ("transfer", None),  # --attack transfer:SURROGATE --kappa 10 (κ chosen on tuning seeds in docs/attacks.md)
]


def evaluate(model: str, flags: list[str], episodes: int, out: str, extra: list[str] | None = None) -> list[str]:
    return ["zodrive", "evaluate", model, *flags, *(extra or []), "--episodes", str(episodes),
            "--seed", str(SEED), "--out", out, "--no-progress"]


def cells() -> list[tuple[str, list[str]]]:
    """(name, argv) in the order they run: the ε 0.05 table first, then the rules, then ε 0.02."""
    out: list[tuple[str, list[str]]] = []
    for key, d in DRIVERS.items():
        if "surrogate_flags" in d:
            out.append((f"surrogate-{key}", ["zodrive", "surrogate-train", d["model"], *d["flags"],
                                              *d["surrogate_flags"], "--out", d["surrogate"]]))
    for eps in EPSILONS:
        for key, d in DRIVERS.items():
            if eps == EPSILONS[0]:
                out.append((f"{key}-clean", evaluate(d["model"], d["flags"], d["episodes"], f"{REL}/{key}-clean")))
                preset = d["flags"][:2]  # a constant reads nothing: the same preset and seeds, no attack
                for b in ("slower", "faster"):
                    out.append((f"{key}-{b}", evaluate(f"baseline:{b}", preset, d["episodes"], f"{REL}/{key}-{b}")))
            for name, flags in THREATS:
                if flags is None:
                    flags = ["--attack", f"transfer:{d['surrogate']}", "--kappa", "10"]
                cell = f"{key}-{name}-{eps}"
                out.append((cell, evaluate(d["model"], d["flags"], d["episodes"], f"{REL}/{cell}",
                                           [*flags, "--eps", str(eps)])))
        if eps == EPSILONS[0]:
            out.extend(rules_cells())
    return out


def rules_cells() -> list[tuple[str, list[str]]]:
    """The decision-based attack against the hand-written rules (outputs already one-hot), at ε 0.02 and 0.05."""
    rules = ["--preset", "highway-fast"]
    out = [("rules-clean", evaluate("baseline:rules", rules, RULES_EPISODES, f"{REL}/rules-clean"))]
    for eps in (0.05, 0.02):
        out.append((f"rules-decision-{eps}", evaluate(
            "baseline:rules", rules, RULES_EPISODES, f"{REL}/rules-decision-{eps}",
            ["--attack", "hsja", "--access", "decision", *BUDGET, "--eps", str(eps)])))
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("names", nargs="*", help="only these cells (default: every cell)")
    p.add_argument("--list", action="store_true", help="print the commands and run nothing")
    a = p.parse_args()
    todo = cells()
    known = {n for n, _ in todo}
    unknown = [n for n in a.names if n not in known]
    if unknown:
        p.error(f"unknown cell(s) {unknown}; known: {sorted(known)}")
    if a.names:
        todo = [(n, c) for n, c in todo if n in a.names]
    if a.list:
        for n, c in todo:
            print(f"{n}: {shlex.join(c)}")
        return 0
    RUNS.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    failed = []
    for n, c in todo:
        if c[1] == "surrogate-train" and (ROOT / c[-1] / "surrogate.json").exists():
            print(f"{n}: kept ({c[-1]}/surrogate.json exists)", flush=True)
            continue
        print(f"{n}: {shlex.join(c)}", flush=True)
        with open(RUNS / f"{n}.log", "a") as log:
            log.write(f"$ {shlex.join(c)}\n")
            log.flush()
            rc = subprocess.run(c, cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT).returncode
        print(f"{n}: exit {rc}", flush=True)
        if rc:
            failed.append(n)
    if failed:
        print(f"failed: {failed}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
