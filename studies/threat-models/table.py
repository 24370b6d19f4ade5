"""Print the study's tables (markdown) from each cell's summary.json under studies/threat-models/runs/.

    python studies/threat-models/table.py > studies/threat-models/table.txt

Every number comes from a summary.json that `zodrive evaluate` wrote: return and its 95 % CI (`ci95`),
collisions and their CI (`collision_ci95`), success (`attack_success_rate`, its CI `attack_success_ci95`,
base rate `target_base_rate`), queries per attacked step (`queries_per_step`: the attack's queries over the
steps it attacked), the share of decisions attacked (`attacked_share`, only with a frequency budget),
mean episode length, mean speed (`mean_speed`), and the share of all decisions on which the victim
took FASTER and SLOWER (`action_share`, indices 3 and 4 of the meta-actions). A cell whose folder has
no summary.json, or fewer episodes than run.py asks, is printed as missing / partial.
"""

from __future__ import annotations

import sys
from pathlib import Path

from zodrive.evaluation import store

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import run  # noqa: E402  (the cells' names, models and episode counts)

THREATS = [
    ("clean", "clean (no attack)"),
    ("slower", "constant brake (`baseline:slower`)"),
    ("faster", "always FASTER (`baseline:faster`)"),
    ("score", "score access, every row (`zo-signsgd`)"),
    ("decision", "decision access (`hsja --access decision`)"),
    ("one-object", "one object (`zo-signsgd --vehicles 1`)"),
    ("share-0.1", "10 % of steps (`zo-signsgd --attack-share 0.1`)"),
    ("transfer", "transfer, 0 queries (`transfer:SURROGATE --kappa 10`)"),
]
HEAD = ("| Threat model | ε | Return (95% CI) | Collisions (95% CI) | Success (95% CI) [base rate] "
        "| Queries per attacked step | Attacked steps | Mean length | Speed (m/s) | FASTER / SLOWER taken |\n"
        + "|---" * 10 + "|")


def pct(x: float | None, digits: int = 0) -> str:
    return "–" if x is None or x != x else f"{100 * x:.{digits}f}%"


def row(label: str, eps: str, folder: Path, episodes: int) -> str:
    if not store.exists(folder):  # a folder or a cell of runs.jsonl.gz (zodrive pack)
        return f"| {label} | {eps} | missing (`{folder.name}`) | | | | | | | |"
    s = store.summary(folder)
    partial = "" if s["episodes"] == episodes and s["seed"] == run.SEED else \
        f" (partial: {s['episodes']} episodes from seed {s['seed']})"
    ret = f"{s['mean_return']:.2f} ({s['ci95'][0]:.2f}–{s['ci95'][1]:.2f}){partial}"
    col = f"{pct(s['collision_rate'])} ({pct(s['collision_ci95'][0])}–{pct(s['collision_ci95'][1])})"
    if s.get("attack"):
        ci = s.get("attack_success_ci95") or [None, None]
        succ = f"{pct(s['attack_success_rate'], 1)} ({pct(ci[0], 1)}–{pct(ci[1], 1)}) [{pct(s['target_base_rate'], 1)}]"
        q = f"{s['queries_per_step']:.1f}"
        share = s.get("attacked_share")
        decisions = s["victim_rows"]["decisions"]
        attacked = f"{pct(share, 1)} of {decisions}" if share is not None else f"every step ({decisions})"
    else:
        succ = q = attacked = "–"
    a = s.get("action_share")  # LANE_LEFT, IDLE, LANE_RIGHT, FASTER, SLOWER: what the victim took, all decisions
    acts = f"{pct(a[3], 1)} / {pct(a[4], 1)}" if a and len(a) == 5 else "–"
    cells = [label, eps, ret, col, succ, q, attacked, f"{s['mean_length']:.1f}", f"{s['mean_speed']:.1f}", acts]
    return "| " + " | ".join(cells) + " |"


def driver_table(key: str, d: dict) -> str:
    n = d["episodes"]
    lines = [f"### {key}: `{d['model']}` ({' '.join(d['flags'])}), {n} episodes, seeds "
             f"{run.SEED}..{run.SEED + n - 1}", "", HEAD]
    for name, label in THREATS[:3]:
        lines.append(row(label, "–", run.RUNS / f"{key}-{name}", n))
    for eps in run.EPSILONS:
        for name, label in THREATS[3:]:
            lines.append(row(label, str(eps), run.RUNS / f"{key}-{name}-{eps}", n))
    return "\n".join(lines)


def rules_table() -> str:
    n = run.RULES_EPISODES
    lines = [f"### baseline:rules (--preset highway-fast), {n} episodes, seeds {run.SEED}..{run.SEED + n - 1}", "",
             HEAD, row("clean (no attack)", "–", run.RUNS / "rules-clean", n)]
    for eps in (0.02, 0.05):
        lines.append(row("decision access (`hsja --access decision`)", str(eps), run.RUNS / f"rules-decision-{eps}", n))
    return "\n".join(lines)


def main() -> None:
    parts = [driver_table(k, d) for k, d in run.DRIVERS.items()]
    parts.append(rules_table())
    print("\n\n".join(parts))


if __name__ == "__main__":
    main()
