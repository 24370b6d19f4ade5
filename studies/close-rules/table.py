"""The close-rules table: teacher, DAgger students and baselines on tuning (900000+) and evaluation
(100000+) seeds, from each run's summary.json. Usage: python studies/close-rules/table.py > results/close-rules/table.md"""
import json
from pathlib import Path

from zodrive.evaluation import store

HERE = Path(__file__).resolve().parents[2] / "results" / "close-rules"  # the data: results/close-rules
ROWS = [("baseline:close-rules (teacher)", "tune-teacher", "eval", None)]
ROWS += [(f"DAgger {r} rounds, seed {s}", f"tune-dagger{r}-s{s}", f"eval-dagger{r}-s{s}", f"train-dagger{r}-s{s}.json")
         for r in (6, 10) for s in (20000, 21000, 22000)]


def cell(folder: str) -> str:
    if not store.exists(HERE / folder):  # its folder, or its line in results/close-rules.jsonl.gz
        return "– | – | – | –"
    s = store.summary(HERE / folder)
    low, high = s["ci95"]
    return (f"{s['mean_return']:.2f} ({low:.2f}–{high:.2f}) | {100 * s['collision_rate']:.0f}% | "
            f"{s['mean_speed']:.1f} | {s['lane_changes_per_episode']:.2f}")


def agreement(train: str | None) -> str:
    """Agreement with the teacher on held-out states the final student drives into (seeds 90000+)."""
    path = HERE / train if train else None
    return f"{json.loads(path.read_text())['heldout_agreement']:.4f}" if path and path.exists() else "–"


print("| Driver | Held-out agreement | Tuning: return (95% CI) | coll. | m/s | lane ch. | Evaluation: return (95% CI) | coll. | m/s | lane ch. |")
print("|---|---|---|---|---|---|---|---|---|---|")
for name, tune, evaluation, train in ROWS:
    print(f"| {name} | {agreement(train)} | {cell(tune)} | {cell(evaluation)} |")
