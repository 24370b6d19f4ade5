"""Model cards: how a model was made and how it scores, from its own records. This module writes every card
(`save_card`): a shipped model's from its run folder (`card_text`, `zodrive card FOLDER ...`), a zoo model's from
its run and its bench row (`zodrive.bench.zoo_card.zoo_cards`, `python zoo/card.py`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from zodrive.config import read_yaml
from zodrive.errors import ZodriveError
from zodrive.evaluation import store
from zodrive.evaluation.report import or_dash
from zodrive.runinfo import read_json, sha256, write_atomic

PAPER_TARGETS = {"dqn": 310.58, "ddpg": 232.78}
PAPER_BUDGETS = {"dqn": 20_000, "ddpg": 120_000}


RESULT = ("mean_return", "ci95", "episodes", "seed")  # what `_result_line` reads first


def load_record(path: Path, needs: tuple[str, ...] = ()) -> dict[str, Any]:
    """A record of a model's folder (JSON, or YAML by its suffix); a missing or damaged one, or one without a key
    of `needs`, is one line naming it."""
    if not path.is_file():
        raise ZodriveError(f"{path} is missing (train and evaluate into the folder first)")
    if path.suffix == ".yaml":
        data = read_yaml(path)
        missing = [k for k in needs if k not in data]
        if missing:
            raise ZodriveError(f"run record {path} has no {missing[0]!r} (damaged, or not a record zodrive wrote)")
        return data
    return read_json(path, needs=needs)


def _summary(evaluation: Path, needs: tuple[str, ...] = ()) -> dict[str, Any]:
    """An evaluation's summary, from its folder or from its line in a pack (`evaluation.store`)."""
    if store.is_live(evaluation) or not store.exists(evaluation):
        return load_record(evaluation / "summary.json", needs)  # a missing one is named as the file
    return store.summary(evaluation, needs)


def _result_line(summary: dict[str, Any]) -> str:
    low, high = summary["ci95"]
    return (f"{summary['mean_return']:.2f} (95% CI {low:.2f}-{high:.2f}; {summary['pct_of_max']:.2f}% of the maximum), "
            f"collision rate {summary['collision_rate']:.0%}, off-road {summary.get('offroad_rate', 0):.0%}, "
            f"mean speed {summary['mean_speed']:.1f} m/s, "
            + (f"{summary['lane_changes_per_episode']:.1f} lane changes per episode, "
               f"{summary['mean_distance']:.0f} m travelled, "
               if summary.get("lane_changes_per_episode") is not None else "")
            + f"right lane {summary['right_lane_share']:.0%}, {summary['episodes']} episodes, seeds "
            f"{summary['seed']}..{summary['seed'] + summary['episodes'] - 1}")


def seed_table(folders: list[Path]) -> list[str]:
    """Markdown lines: each training seed's evaluation, then the median and range across seeds."""
    import numpy as np

    rows = []
    for folder in folders:
        train, summary = (load_record(folder / "train.json", ("seed",)),
                          _summary(folder / "eval", ("mean_return",)))
        rows.append((train["seed"], folder, summary))
    lines = ["| Training seed | Run | Mean return (95% CI) | Collisions | Off-road | Speed (m/s) | Lane changes/ep |",
             "|---|---|---|---|---|---|---|"]
    for seed, folder, s in sorted(rows, key=lambda r: r[0]):
        lines.append(f"| {seed} | `{folder.name}` | {s['mean_return']:.2f} ({s['ci95'][0]:.2f}–{s['ci95'][1]:.2f}) | "
                     f"{s['collision_rate']:.0%} | {s.get('offroad_rate', 0):.0%} | {s['mean_speed']:.1f} | "
                     f"{or_dash(s.get('lane_changes_per_episode'), '{:.1f}')} |")
    lines.append("")
    for key, label, fmt in (("mean_return", "Mean return", "{:.2f}"), ("collision_rate", "Collisions", "{:.0%}"),
                            ("mean_speed", "Speed (m/s)", "{:.1f}"),
                            ("lane_changes_per_episode", "Lane changes/ep", "{:.1f}")):
        values = np.array([s.get(key, np.nan) for _, _, s in rows], dtype=float)
        lines.append(f"- {label} across {len(values)} seeds: median " + fmt.format(np.median(values))
                     + ", range " + fmt.format(values.min()) + "–" + fmt.format(values.max()))
    lines.append(_iqm_line([folder for _, folder, _ in rows]))
    return lines


def _iqm_line(folders: list[Path]) -> str:
    """rliable's IQM over seeds x episodes, from each seed's per-episode returns."""
    from zodrive.evaluation.stats import iqm_over_seeds

    per_seed = []
    for folder in folders:
        rows = store.episodes(folder / "eval", needs=("seed", "return"), missing_ok=True)
        episodes = sorted(rows, key=lambda e: e["seed"])
        per_seed.append([e["return"] for e in episodes])
    if len({len(r) for r in per_seed}) != 1:
        return "- IQM: not computed (the seeds were evaluated on different numbers of episodes)"
    iqm = iqm_over_seeds(per_seed)
    if iqm is None:
        return "- IQM over seeds x episodes: install `zodrive[stats]` (rliable) to compute it"
    return (f"- Interquartile mean over {len(per_seed)} seeds x {len(per_seed[0])} episodes (rliable, stratified "
            f"bootstrap 95% CI): {iqm[0]:.2f} ({iqm[1]:.2f}–{iqm[2]:.2f})")


def _selection_lines(folder: Path) -> list[str]:
    """The checkpoint `zodrive select` picked on tuning seeds, with every candidate's numbers."""
    if not (folder / "selected.json").is_file():
        return []
    from zodrive.experiments.select import selection_markdown

    choice = load_record(folder / "selected.json", ("selected", "criterion"))
    return ["", f"`model.zip` is the checkpoint at step {choice['selected']['steps']:,}, picked by `zodrive select` "
            f"({choice['criterion']}; never the evaluation seeds):", "", selection_markdown(choice)]


ROBUST_KINDS = {"adversarial": "adversarially trained (Algorithm 2)", "sa-dqn": "SA-regularized (SA-DQN)",
                "sa-ddpg": "SA-regularized (SA-DDPG)", "distill": "robustly distilled"}


def _attacked_lines(folders: list[Path]) -> list[str]:
    """One line per attacked evaluation: the attack, its eps and what the policy scored."""
    lines = []
    for folder in folders:
        s = _summary(folder, RESULT)
        config = s.get("attack_config") or {}
        options = ", ".join(f"{k} {config[k]}" for k in ("max_change", "target") if config.get(k) not in (None, "auto"))
        lines.append(f"- under **{s.get('attack')}** (ε {s.get('eps')}"
                     + (f", through the {s['defense']} filter" if s.get("defense") else "")
                     + (f", {options}" if options else "") + f"; `{folder}`): {_result_line(s)}; "
                     f"attack success {or_dash(s.get('attack_success_rate'), '{:.0%}')}, "
                     f"{or_dash(s.get('queries_per_step'), '{:.0f}')} queries per step")
    return lines


def save_card(path: Path, text: str) -> Path:
    """Write a card's text to `path` (a model folder's CARD.md): the one writer of shipped and zoo cards."""
    write_atomic(path, text)
    return path


def write_card(folder: Path, *, baseline: Path | None = None, evaluation: Path | None = None,
               notes: list[str] | None = None, seeds: list[Path] | None = None,
               attacked: list[Path] | None = None) -> Path:
    """Write `folder/CARD.md`: `card_text` of the same arguments."""
    return save_card(folder / "CARD.md", card_text(folder, baseline=baseline, evaluation=evaluation, notes=notes,
                                                   seeds=seeds, attacked=attacked))


def card_text(folder: Path, *, baseline: Path | None = None, evaluation: Path | None = None,
              notes: list[str] | None = None, seeds: list[Path] | None = None,
              attacked: list[Path] | None = None) -> str:
    """The text of `folder/CARD.md`, from run.json, train.json, config.yaml and an evaluation's
    summary.json (default `folder/eval`); `attacked`: evaluation folders of the model under
    attack, listed with their attack and eps. Paths are written as given (the card names its command)."""
    run = load_record(folder / "run.json", ("command", "versions"))
    train = load_record(folder / "train.json", ("algo", "seed", "total_timesteps"))
    config = load_record(folder / "config.yaml", ("preset",))
    summary = _summary(evaluation or folder / "eval", (*RESULT, "command"))
    algo = train["algo"]
    robust = train.get("kind") in ROBUST_KINDS
    recipe = config.get("recipe") or {k: config[k] for k in ("source_model", "attack", "method", "steps", "warmup")
                                      if config.get(k) is not None}
    kind = ROBUST_KINDS[train["kind"]] + " " if robust else ""
    if robust and train["kind"] == "distill" and not train.get("method", {}).get("kappa"):  # no adversarial term
        kind = "behaviour-cloned " + ("(DAgger) " if train["method"].get("rounds") is not None else "")
    lines = [
        f"# {folder.name}: {kind}{algo.upper()} on the `{config['preset']['name']}` preset",
        "",
        "Made by this repository's own commands:",
        "",
        "```",
        run["command"],
        *run.get("continued_by", []),
        *([load_record(folder / "selected.json", ("command",))["command"]]
          if (folder / "selected.json").is_file() else []),
        summary["command"],
        f"zodrive card {folder}" + (f" --baseline {baseline}" if baseline else "")
        + (f" --eval {evaluation}" if evaluation else "")
        + (" --seeds " + " ".join(str(p) for p in seeds) if seeds else "")
        + (" --attacked " + " ".join(str(p) for p in attacked) if attacked else "")
        + "".join(f" --note {n!r}" for n in notes or []),
        "```",
        "",
        f"- training seed: {train['seed']}; steps: {train['total_timesteps']:,}; "
        f"wall time: {train['wall_time_s'] / 60:.1f} min ({train['steps_per_s']:.0f} steps/s on a 2-core CPU)",
        "- versions: " + ", ".join(f"{k} {v}" for k, v in run["versions"].items()),
        f"- `model.zip` SHA-256: `{sha256(folder / 'model.zip')}` (shipped models are listed in "
        "`models/SHA256SUMS`; zodrive checks the sum before it lets stable-baselines3 unpickle the file)",
        "",
        *_selection_lines(folder),
        "## Evaluation",
        "",
        f"**Mean return {_result_line(summary)}.**",
        "",
    ]
    if not robust:
        lines.append(f"Paper (Table 1, Initial Training): {PAPER_TARGETS.get(algo, float('nan')):.2f}.")
    elif train["kind"] == "adversarial":
        lines.append("Trained further on attacked observations (paper Algorithm 2); "
                     f"{train.get('attack_queries', 0):,} attack queries during training.")
    else:
        method = train.get("method") or {}
        lines.append(f"Method: {method.get('name')} ({method.get('reference', '')}), ε {method.get('eps')}, "
                     + ", ".join(f"{k} {v}" for k, v in method.items() if k not in ("name", "reference", "eps"))
                     + f"; from `{train.get('source_model')}`.")
    if summary.get("action_share"):
        from zodrive.envs import ACTION_NAMES

        lines.append("Action shares: "
                     + ", ".join(f"{n} {s:.1%}" for n, s in zip(ACTION_NAMES, summary["action_share"])) + ".")
    if attacked:
        lines += ["", "Under attack (the same evaluation seeds, from the first; each line gives its episodes):", ""] \
            + _attacked_lines(attacked)
    if not robust and recipe.get("hyperparameters"):
        changed = ", ".join(f"{k}={v}" for k, v in recipe["hyperparameters"].items())
        budget = ("the step budget is the paper's" if train["total_timesteps"] == PAPER_BUDGETS.get(algo)
                  else f"{train['total_timesteps']:,} steps; the paper's budget is {PAPER_BUDGETS.get(algo, 0):,}")
        lines += ["", f"Changed from stable-baselines3's defaults ({budget}): {changed}."]
    if baseline is not None:
        base = _summary(baseline, RESULT)
        lines += ["", f"With SB3's default hyperparameters (`{algo}-paper` recipe, same budget and seeds): "
                      f"{_result_line(base)}."]
    if seeds:
        lines += ["", "## Training seeds", "", "Every seed trained with the same recipe and evaluated on the same "
                  "episodes; report the median and range, not the best seed.", ""] + seed_table(seeds)
    if notes:
        lines += ["", "## Notes", ""] + [f"- {n}" for n in notes]
    lines += [
        "",
        "## Recipe" if not robust else "## Robust training",
        "",
        "```yaml",
        yaml.safe_dump(recipe, sort_keys=False).rstrip(),
        "```",
        "",
        "The resolved environment preset is in `config.yaml`; the training curve in `monitor.monitor.csv`"
        " (episode returns) and `progress.csv` (SB3 logger).",
        "",
    ]
    return "\n".join(lines)
