"""`zodrive select`: pick a training run's checkpoint on tuning seeds, never on evaluation seeds.

Deep-RL training curves rise and fall; the last checkpoint is not the best one. Each
checkpoint (and the final model) is evaluated greedily on the same tuning episodes (seeds
50000+, disjoint from the evaluation seeds 100000+), each as an ordinary resumable
evaluation in RUN/selection/<steps>/; the one with the highest mean return is written to
RUN/selected.json. Its evaluation-seed numbers are then measured separately, by `evaluate`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from zodrive.training.recipes import checkpoints
from zodrive.config import read_yaml
from zodrive.envs import load_preset
from zodrive.errors import ZodriveError
from zodrive.evaluation.evaluate import EvalJob, evaluate
from zodrive.runinfo import command_line, write_json
from zodrive.seeds import TUNING_SEED


def select_checkpoint(run: Path, episodes: int, *, from_step: int = 0, workers: int = 1,
                      progress: bool = True) -> dict[str, Any]:
    """Evaluate every checkpoint of `run` from `from_step` on; return and write the choice."""
    config_file = run / "config.yaml"
    if not config_file.is_file():
        raise ZodriveError(f"{run} is not a training run folder (no config.yaml)")
    config = read_yaml(config_file)
    algo = config["recipe"]["algo"]
    preset = config.get("preset") or load_preset(config["recipe"]["preset"])  # as trained
    candidates = [(steps, path) for steps, path in checkpoints(run, algo) if steps >= from_step]
    final = run / "model.zip"
    if final.is_file():
        done = max((s for s, _ in candidates), default=-1)
        total = int(config["recipe"].get("total_timesteps", done + 1))
        if total > done and total >= from_step:  # the final model is a candidate only from its step
            candidates.append((total, final))
    if not candidates:
        raise ZodriveError(f"{run} has no checkpoints from step {from_step} on")
    rows = []
    for steps, path in candidates:
        job = EvalJob(model=str(path), preset=preset, seed=TUNING_SEED)
        s = evaluate(job, episodes, run / "selection" / str(steps), workers=workers, progress=progress)
        rows.append({"steps": steps, "model": str(path), "mean_return": s["mean_return"], "ci95": s["ci95"],
                     "collision_rate": s["collision_rate"], "offroad_rate": s.get("offroad_rate", 0.0),
                     "mean_speed": s["mean_speed"], "lane_changes_per_episode": s["lane_changes_per_episode"]})
    best = max(rows, key=lambda r: r["mean_return"])
    choice = {"command": command_line(), "selected": best,
              "criterion": f"highest mean return on {episodes} tuning episodes "
              f"(seeds {TUNING_SEED}..{TUNING_SEED + episodes - 1})", "candidates": rows}
    write_json(run / "selected.json", choice)
    return choice


def selection_markdown(choice: dict[str, Any]) -> str:
    lines = ["| Steps | Return (95% CI) | Collisions | Off-road | Speed (m/s) | Lane changes/ep |",
             "|---|---|---|---|---|---|"]
    for r in choice["candidates"]:
        mark = " ←" if r["steps"] == choice["selected"]["steps"] else ""
        lines.append(f"| {r['steps']:,}{mark} | {r['mean_return']:.2f} ({r['ci95'][0]:.2f}–{r['ci95'][1]:.2f}) | "
                     f"{r['collision_rate']:.0%} | {r['offroad_rate']:.0%} | {r['mean_speed']:.1f} | "
                     f"{r['lane_changes_per_episode']:.1f} |")
    return "\n".join(lines) + "\n"
