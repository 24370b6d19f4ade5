"""`zodrive reproduce`: the paper's whole study in one resumable command.

Stages, each skipped when its output is already on disk (so an interrupted run resumes):
  1. models    shipped ones from models/, or (--retrain) train + adversarially train anew
  2. cells     8 evaluations = {DQN, DDPG} x {Initial, Under Attack, Adversarial, After}
  3. figures   Fig. 2 loss trace, Fig. 3 attacked crash (PNG + GIF), Figs. 4/5 rewards
  4. robustness  return against eps under the strongest attack, for the driver (with and
               without the kinematic filter), the defended driver and the baselines (out/robustness)
  5. report    Table 1 (CSV, JSON, Markdown) beside the paper's numbers, then the robustness
               section; report.md/.html
"""

from __future__ import annotations

import json
import logging
import sys
import time
from pathlib import Path
from typing import Any

from zodrive.policies.loading import model_file
from zodrive.policies.policy import resolve
from zodrive.attacks.spec import AttackSpec, load_attack
from zodrive.config import models_dir
from zodrive.envs import load_preset
from zodrive.errors import ZodriveError
from zodrive.experiments.cells import Cell, run_cells
from zodrive.evaluation import store
from zodrive.evaluation.evaluate import DEFAULT_ENVS, DEFAULT_EVAL_SEED, EvalJob, same_evaluation
from zodrive.experiments.paper import ADV_STEPS
from zodrive.runinfo import read_json, write_atomic, write_json

log = logging.getLogger(__name__)

PRESET_OF = {"dqn": "discrete", "ddpg": "continuous"}
# Policies that ignore their observation (or read the simulator), evaluated beside each agent:
# a number one of these also reaches is not a result; and a hand-written driver on the same
# observation (baseline:rules), the bar a learned driver has to clear.
BASELINE_ROWS = {
    "dqn": ("baseline:slower", "baseline:faster", "baseline:idm-mobil", "baseline:rules"),
    "ddpg": ("baseline:brake", "baseline:accelerate", "baseline:idm-mobil"),
}


# The robustness section (issue "Defenses that hold"): each system under its strongest attack
# per eps (black-box, the defense-aware drift-limited one, and white-box PGD where there are
# gradients), the same seeds in every cell. Shipped models are named by their folder in models/
# (`--retrain` retrains Table 1's paper-budget models only; this section always uses the shipped
# driver and defended models).
# (policy, defenses, extra attacks)
ROBUSTNESS_SYSTEMS: tuple[tuple[str, tuple[str | None, ...], tuple[str, ...]], ...] = (
    ("dqn-driver", (None, "kinematic"), ()),
    ("dqn-robust", (None,), ()),
    ("dqn-sa", (None, "kinematic"), ()),   # SA-DQN, eps 0.05, kappa 0.5: comes out as always-SLOWER
    ("dqn-at", (None,), ()),               # Algorithm 2, eps 0.2: likewise
    ("baseline:robust-rules@0.02", (None,), ("random-search-slower",)),  # it can only be made careful
    ("baseline:rules", (None,), ("random-search-slower",)),
    ("baseline:slower", (None,), ()),
    ("ddpg-driver", (None, "kinematic"), ()),
    ("ddpg-robust", (None,), ()),
    ("baseline:brake", (None,), ()),
)
ROBUSTNESS_ATTACKS = ("random-search", "random-search-smooth", "pgd")
ROBUSTNESS_ATTACK_SET = ["patience=10"]  # a step stops after 10 iterations without progress
ROBUSTNESS_EPS = (0.02, 0.05, 0.1, 0.2)


def prepare_models(out: Path, *, retrain: bool, quick: bool, progress: bool) -> dict[str, Path]:
    """Paths of the four models: shipped, or retrained into out/models (resumable)."""
    if not retrain:
        paths: dict[str, Path] = {name: models_dir() / name for name in ("dqn", "dqn-adv", "ddpg", "ddpg-adv")}
        for name, path in paths.items():
            model_file(path)  # a clear error if a shipped model is missing
        return paths
    from zodrive.training.recipes import load_recipe, train
    from zodrive.training.adversarial import adversarial_train

    paths = {}
    for algo in ("dqn", "ddpg"):
        base, adv = out / "models" / algo, out / "models" / f"{algo}-adv"
        overrides = ["total_timesteps=2000"] if quick else []
        if not (base / "model.zip").is_file():
            train(load_recipe(algo, overrides), base, progress_bar=progress)
        if not (adv / "model.zip").is_file():
            adversarial_train(base, load_preset(PRESET_OF[algo]), load_attack("zo-signsgd"),
                              500 if quick else ADV_STEPS[algo], adv, progress_bar=progress,
                              trust=True)  # trained by this very run
        paths[algo], paths[f"{algo}-adv"] = base, adv
    return paths


def cells(models: dict[str, Path], spec: AttackSpec) -> list[tuple[str, str, str, AttackSpec | None]]:
    """(algo, row, model, attack) for the eight cells of Table 1 and the baseline rows."""
    table = []
    for algo in ("dqn", "ddpg"):
        table += [
            (algo, "initial", resolve(models[algo]).ref, None),
            (algo, "under_attack", resolve(models[algo]).ref, spec),
            (algo, "adversarial", resolve(models[f"{algo}-adv"]).ref, spec),
            (algo, "after", resolve(models[f"{algo}-adv"]).ref, None),
        ]
        table += [(algo, baseline.replace(":", "-"), baseline, None) for baseline in BASELINE_ROWS[algo]]
    return table


def reproduce(out: Path, *, episodes: int = 100, workers: int = 2, quick: bool = False,
              retrain: bool = False, progress: bool = True, seed: int = DEFAULT_EVAL_SEED,
              backend: str = "local", address: str | None = None, robustness_episodes: int = 10,
              envs: int = DEFAULT_ENVS) -> dict[str, Any]:
    """Run (or resume) the whole reproduction into `out`; returns the Table 1 data.
    `robustness_episodes` episodes per robustness cell (0: no robustness section)."""
    from zodrive.experiments.report import build_table, write_report

    if episodes < 1:
        raise ZodriveError(f"episodes must be >= 1, not {episodes}")
    if quick:
        episodes = min(episodes, 5)
    out.mkdir(parents=True, exist_ok=True)
    timings: dict[str, float] = read_json(out / "timings.json", "timings") if (out / "timings.json").is_file() else {}
    start = time.perf_counter()
    models = prepare_models(out, retrain=retrain, quick=quick, progress=progress)
    spec = load_attack("zo-signsgd")
    summaries: dict[str, dict[str, dict[str, Any]]] = {"dqn": {}, "ddpg": {}}
    todo: list[tuple[str, str, Cell]] = []
    for algo, row, model, attack in cells(models, spec):
        folder = out / "cells" / f"{algo}-{row}"
        job = EvalJob(model=model, preset=load_preset(PRESET_OF[algo]),
                      attack=attack.to_dict() if attack else None, seed=seed)
        found = store.read(folder) if store.exists(folder) else None  # its folder, or its line in a pack
        if found is not None and found.summary is not None and found.summary["episodes"] == episodes \
                and found.key is not None and same_evaluation(found.key, json.loads(json.dumps(job.key()))):
            summaries[algo][row] = found.summary
            continue
        todo.append((algo, row, Cell(job, episodes, folder)))
        if progress:
            print(f"cell {algo}-{row}: {episodes} episodes of {model}" + (" under attack" if attack else ""),
                  file=sys.stderr)
    last = [time.perf_counter()]

    def done(i: int, summary: dict[str, Any]) -> None:
        algo, row, _ = todo[i]
        summaries[algo][row] = summary
        now = time.perf_counter()
        timings[f"cell {algo}-{row}"] = round(now - last[0], 1)  # since the previous cell ended (report.TIMINGS)
        last[0] = now
        write_json(out / "timings.json", timings)

    run_cells([cell for _, _, cell in todo], backend=backend, workers=workers, progress=progress,
              address=address, on_done=done, envs=envs)
    figures = make_figures(out, models, spec, quick=quick)
    curve = robustness(out / "robustness", episodes=min(robustness_episodes, 1) if quick else robustness_episodes,
                       quick=quick, workers=workers, progress=progress, seed=seed, backend=backend, address=address,
                       envs=envs)
    table = build_table(summaries, out)
    runs = sum(1 for key in timings if key.startswith("invocation "))
    timings[f"invocation {runs + 1} total"] = round(time.perf_counter() - start, 1)
    write_json(out / "timings.json", timings)
    write_report(out, table, figures, timings, episodes=episodes, retrain=retrain, quick=quick,
                 robustness_episodes=curve)
    return table


def robustness(out: Path, *, episodes: int, quick: bool, **run: Any) -> int:
    """The robustness grid into `out` (resumable cells, robustness.md, robustness.png); returns
    the episodes per cell (0: skipped). Quick mode: eps 0.2 and random search only."""
    from zodrive.drivers.baselines import is_baseline
    from zodrive.experiments.compare import compare, plot_robustness, robustness_markdown, write_tables

    if episodes < 1:
        return 0
    attacks, eps = (["random-search"], [0.2]) if quick else (list(ROBUSTNESS_ATTACKS), list(ROBUSTNESS_EPS))
    rows: list[dict[str, Any]] = []
    for name, defenses, extra in ROBUSTNESS_SYSTEMS:
        model = name if is_baseline(name) else str(models_dir() / name)
        rows += compare([model], attacks + ([] if quick else list(extra)), eps, episodes, out, defenses=list(defenses),
                        attack_set=ROBUSTNESS_ATTACK_SET, claim=False, **run)
    write_tables(rows, out)  # each compare call wrote its own rows only
    write_atomic(out / "robustness.md", robustness_markdown(rows))  # also with one eps (quick mode)
    plot_robustness(rows, out / "robustness.png")
    return episodes


def make_figures(out: Path, models: dict[str, Path], spec: AttackSpec, *, quick: bool) -> dict[str, Any]:
    """Figures 2-5 (each skipped if already drawn)."""
    from zodrive.experiments.figures import loss_trace, plot_loss, plot_training_rewards

    fig = out / "figures"
    info_path = fig / "figures.json"
    info: dict[str, Any] = read_json(info_path, "figure record") if info_path.is_file() else {}
    if not (fig / "fig2_loss.png").is_file():
        trace_spec = spec.with_overrides(early_stop=False, l2_weight=0.1, warm_start=False, patience=None)
        traces = {algo.upper(): loss_trace(str(models[algo]), load_preset(PRESET_OF[algo]), trace_spec,
                                           max_states=60 if quick else 200)
                  for algo in ("dqn", "ddpg")}
        plot_loss(traces, fig / "fig2_loss.png")
        info["fig2"] = {k: {kk: v[kk] for kk in ("found", "state", "linf") if kk in v} for k, v in traces.items()}
        write_json(info_path, info)
    if not (fig / "fig3_attacked_episode.png").is_file():
        info["fig3"] = render_crash(models["dqn"], spec, fig, tries=3 if quick else 10)
        write_json(info_path, info)
    for algo, number in (("ddpg", 4), ("dqn", 5)):
        png = fig / f"fig{number}_{algo}_adversarial_training.png"
        monitor = Path(models[f"{algo}-adv"]) / "monitor.monitor.csv"
        if not png.is_file() and monitor.is_file():
            info[f"fig{number}"] = plot_training_rewards(
                monitor, png, f"{algo.upper()}: reward per episode, adversarial training")
            write_json(info_path, info)
    return info


def render_crash(model: Path, spec: AttackSpec, fig: Path, *, tries: int) -> dict[str, Any]:
    """Fig. 3: the first attacked DQN episode (from seed 100000) that ends in a collision."""
    from zodrive.system import make_policy_env
    from zodrive.evaluation.video import record_episode, save_gif, save_png

    victim, env = make_policy_env(str(model), load_preset("discrete"), spec, render_mode="rgb_array")
    for seed in range(DEFAULT_EVAL_SEED, DEFAULT_EVAL_SEED + tries):
        frames, info = record_episode(env, victim, seed)
        if info["crashed"]:
            break
    title = f"DQN under {spec.attack} (eps={spec.eps}) | "
    save_png(frames, fig / "fig3_attacked_episode.png", title=title)
    save_gif(frames, fig / "fig3_attacked_episode.gif", title=title)
    env.close()
    return info
