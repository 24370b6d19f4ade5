"""The zoo's model cards (models/zoo/FAMILY/seed-N/CARD.md), from each run's own records: the command and seed
that trained it (`train.json`), the checkpoint chosen on tuning seeds (`selection.json`), its SHA-256, its bench
row (`results/bench/SCENARIO/NAME/row.json`, `bench.row_folder`) and the row's exact check (`exact.json`
beside it). Nothing in a card is typed by hand; `experiments.card.save_card` writes them, as it writes a shipped card.

The zoo's recipe (zoo/train.py's defaults, zoo/choose_checkpoint.py's tuning episodes, zoo/q_ensemble.py's
checkpoints) is the zoo scripts' own: `python zoo/card.py` passes it in as a `ZooRecipe`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

from zodrive.bench.bench import row_folder
from zodrive.bench.exact_board import read_exact, why_not_shown
from zodrive.bench.row import read_row
from zodrive.drivers.baselines import get_baseline
from zodrive.experiments.card import load_record
from zodrive.runinfo import sha256

NO_ROW = "No bench row yet: `bash zoo/bench_all.sh`."
"""A card's words where its run's bench row is not in the checkout."""
ROBUST_KINDS = {"sa-dqn": "SA-DQN's regularizer (Zhang et al., NeurIPS 2020: the Q-values' argmax held over the "
                          "ε-ball, by PGD)",
                "adversarial": "adversarial training (the paper's Algorithm 2: the agent learns from the observations "
                               "its own attacker perturbs, at every step)"}
"""`zodrive robust-train --method sa | at` runs, by the `kind` their train.json records."""


@dataclass(frozen=True)
class ZooRecipe:
    """What the zoo's scripts do by default: a card's command gives only what a run changed."""

    train_defaults: Mapping[str, Any]
    """zoo/train.py's settings a run may change (`DEFAULTS`)."""
    tuning_episodes: int
    """zoo/choose_checkpoint.py's tuning episodes per candidate (`EPISODES`)."""
    ensemble_steps: tuple[int, ...]
    """zoo/q_ensemble.py's checkpoints (`STEPS`)."""


@dataclass(frozen=True)
class _Zoo:
    root: Path
    recipe: ZooRecipe

    def rel(self, path: Path) -> Path:
        return path.relative_to(self.root)


def zoo_cards(root: Path, recipe: ZooRecipe) -> dict[Path, str]:
    """Every zoo card's path and text under `root` (the repository), by the kind of each run; nothing is written."""
    zoo = _Zoo(root, recipe)
    runs = sorted((root / "models" / "zoo").glob("*/seed-*"))
    members: dict[Path, list[Path]] = {}  # run -> the ensembles built from its checkpoints
    for ensemble in (r for r in runs if (r / "build.json").is_file()):
        for source in load_record(ensemble / "build.json", ("runs",))["runs"]:
            members.setdefault(root / source, []).append(ensemble)
    texts = {}
    for run in runs:
        train = load_record(run / "train.json") if (run / "train.json").is_file() else {}
        if run.parent.name.endswith("-imitation") and (run / "model.zip").is_file():
            texts[run / "CARD.md"] = imitation_card(zoo, run)
        elif train.get("kind") in ROBUST_KINDS:
            texts[run / "CARD.md"] = robust_card(zoo, run)
        elif (run / "build.json").is_file():
            texts[run / "CARD.md"] = ensemble_card(zoo, run)
        elif (run / "selection.json").is_file():
            texts[run / "CARD.md"] = trained_card(zoo, run)
        elif run in members and train:
            texts[run / "CARD.md"] = member_card(zoo, run, members[run])
    return texts


def trained_card(zoo: _Zoo, run: Path) -> str:
    """A DQN trained from scratch by zoo/train.py (a checkpoint chosen on tuning seeds)."""
    train = load_record(run / "train.json")
    selection = load_record(run / "selection.json")
    scenario = train["scenario"]
    path, trust = loader_words(own_network(train))
    start = selection.get("from_step", 0)  # a choice among the checkpoints after exploration ended
    since, flag = (f" among the checkpoints from step {start:,} on", f" --from-step {start}") if start else ("", "")
    first, last = selection["tuning_seeds"]
    flag += f" --episodes {last - first + 1}" if last - first + 1 != zoo.recipe.tuning_episodes else ""
    lines = _trained(zoo, run, train) + [
        f"Checkpoint: `{selection['chosen']}`, the best mean return on tuning seeds {first}–{last}{since} "
        f"(`{path}python zoo/choose_checkpoint.py {zoo.rel(run)} --scenario {scenario}{trust}{flag}`), "
        "copied to `model.zip`.", ""]
    return "\n".join(lines + _bench(zoo, run, scenario))


def member_card(zoo: _Zoo, run: Path, ensembles: list[Path]) -> str:
    """A run trained by zoo/train.py only for its checkpoints' places in ensembles: no checkpoint chosen, no row."""
    names = ", ".join(f"[`{e.parent.name}/{e.name}`](../../{e.parent.name}/{e.name}/CARD.md)" for e in ensembles)
    return "\n".join(_trained(zoo, run, load_record(run / "train.json")) + [
        f"No checkpoint is chosen and the run is not benched on its own: its checkpoints are members of {names}.", ""])


def _trained(zoo: _Zoo, run: Path, train: dict[str, Any]) -> list[str]:
    """The card's title and the command that trained the run."""
    scenario, seed = train["scenario"], train["seed"]
    changed = "".join(f" --{k.replace('_', '-')} {train[k]:g}" if isinstance(v, (int, float))
                      else f" --{k.replace('_', '-')} {train[k]}"
                      for k, v in zoo.recipe.train_defaults.items() if train.get(k, v) != v)  # older runs: defaults
    changed += f" --start-from {train['start_from']}" if "start_from" in train else ""  # a continued run
    changed += " --fast-env" if train.get("fast_env") else ""  # zodrive's copy of the scenario: same weights
    network = (" with the ego-attention network of `zoo/ego_attention.py` (its zips load in zodrive with "
               "`zoo/` on `PYTHONPATH` and `--trust-model`)") if own_network(train) else ""
    more = f" more, to step {train['total_steps']:,}" if "start_from" in train else ""
    return [f"# {run.parent.name} / {run.name}", "",
            f"A DQN for `{scenario}` (highway-env `{train['env_id']}`){network}, trained with plain "
            "stable-baselines3 by",
            f"`python zoo/train.py --scenario {scenario} --seed {seed}{changed} --out {zoo.rel(run)}` "
            f"({train['steps']:,} steps{more}, {train['wall_time_s']:.0f} s).", ""]


def _command_and_scenario(run: Path) -> tuple[str, str]:
    """The command a run records (`run.json`) and its scenario (its config's preset)."""
    return (load_record(run / "run.json", ("command",))["command"],
            load_record(run / "config.yaml", ("preset",))["preset"]["name"])


def imitation_card(zoo: _Zoo, run: Path) -> str:
    """A student cloned by DAgger (`zodrive robust-train --method distill --dagger`): no checkpoint is chosen."""
    train = load_record(run / "train.json", ("method", "seed"))
    command, scenario = _command_and_scenario(run)
    method = train["method"]
    teacher = method["teacher"]
    privileged = (" (it **reads the simulator**: a privileged teacher)" if get_baseline(teacher).reads == "simulator"
                  else " (it reads the same observation as the student)")
    lines = [f"# {run.parent.name} / {run.name}", "",
             f"An MLP policy (the zoo DQN's architecture, a stable-baselines3 DQN zip) for `{scenario}`, cloned from "
             f"`{teacher}`{privileged} by behaviour cloning with DAgger ({method['states']:,} states the teacher "
             f"drives, then {method['rounds']} rounds of {method['states']:,} states the student drives, each "
             f"labelled by the teacher; {method['epochs']} epochs per refit; seed {train['seed']}):", "",
             f"`{command}`", "",
             "No checkpoint is chosen: the student after the last DAgger round is the model. Why this recipe and "
             "not DQN from scratch: `studies/zoo-recipe/README.md`.", ""]
    return "\n".join(lines + _bench(zoo, run, scenario))


def robust_card(zoo: _Zoo, run: Path) -> str:
    """A zoo driver made robust by `zodrive robust-train --method sa|at`: no checkpoint is chosen."""
    train = load_record(run / "train.json", ("source_model", "kind"))
    command, scenario = _command_and_scenario(run)
    source = Path(train["source_model"]).parent
    lines = [f"# {run.parent.name} / {run.name}", "",
             f"The zoo's [`{source.parent.name}/{source.name}`](../../{source.parent.name}/{source.name}/CARD.md) "
             f"for `{scenario}` made robust by {ROBUST_KINDS[train['kind']]}, {train['total_timesteps']:,} more "
             f"steps (the first {train['warmup_steps']:,} acting only), seed {train['seed']}, "
             f"{train['wall_time_s'] / 60:.0f} min on a shared core:", "",
             f"`{command}`", "",
             "No checkpoint is chosen: the model after the last step is the model.", ""]
    return "\n".join(lines + _bench(zoo, run, scenario))


def ensemble_card(zoo: _Zoo, run: Path) -> str:
    """An ensemble built by zoo/q_ensemble.py from runs' checkpoints: nothing trained, no checkpoint chosen."""
    build = load_record(run / "build.json", ("runs", "members", "steps"))
    sources = [Path(r) for r in build["runs"]]
    trains = [load_record(zoo.root / source / "train.json") for source in sources]
    scenario = trains[0]["scenario"]
    runs = " and ".join(f"[`{s.parent.name}/{s.name}`](../../{s.parent.name}/{s.name}/CARD.md) (seed {t['seed']})"
                        for s, t in zip(sources, trains, strict=True))
    members = ", ".join(f"`{path}` (`{digest[:12]}…`)" for path, digest in build["members"].items())
    steps = " --steps " + " ".join(map(str, build["steps"])) if tuple(build["steps"]) != zoo.recipe.ensemble_steps \
        else ""
    k = build.get("pessimism", 0)
    combined = f"the mean less {k:g} standard deviation{'s' * (k != 1)}" if k else "the mean"
    flags = steps + (f" --pessimism {k:g}" if k else "")
    why = "\"An ensemble of a run's last checkpoints\", \"Two runs per seed in one ensemble\"" + (
        ", \"A pessimistic ensemble\"" if k else "")
    lines = [f"# {run.parent.name} / {run.name}", "",
             (f"An ensemble for `{scenario}` (highway-env `{trains[0]['env_id']}`): one stable-baselines3 DQN zip "
              f"whose Q-values are {combined} of the Q-values of {len(build['members'])} checkpoints of the zoo "
              f"run{'s' * (len(sources) > 1)} {runs}: {members}. Nothing is trained and no checkpoint is chosen; it "
              f"is built by `PYTHONPATH=zoo python zoo/q_ensemble.py {' '.join(map(str, sources))} "
              f"{zoo.rel(run)}{flags}`, and loads in zodrive with `zoo/` on `PYTHONPATH` and `--trust-model`. "
              f"Why: `studies/zoo-recipe/README.md`, {why}. A rebuild gives the same weights (`policy.pth`, byte for "
              "byte) in a zip with other bytes: SB3 writes memory addresses into the zip's `data`.")]
    if "from" in build:  # recombined from an earlier ensemble's zip, as the checkpoints are not in the repository
        lines[-1] += (f" This zip was recombined from the members of the ensemble zip with SHA-256 "
                      f"`{build['from_sha256'][:12]}…` (`PYTHONPATH=zoo python zoo/q_ensemble.py --from "
                      f"{build['from']} OUT{flags}`; it was `{build['from']}/model.zip` in the repository's "
                      "history): its `policy.pth` is that zip's, byte for byte.")
    lines.append("")
    return "\n".join(lines + _bench(zoo, run, scenario))


def own_network(train: dict[str, Any]) -> bool:
    """A network of its own (not the MLP): zodrive reads its zips with SB3's loader only."""
    return train.get("net", "mlp") != "mlp"


def loader_words(trusted: bool) -> tuple[str, str]:
    """What a command needs before and after itself to load a zoo zip with a network of its own."""
    return ("PYTHONPATH=zoo ", " --trust-model") if trusted else ("", "")


def row_name(run: Path, scenario: str) -> str:
    """The run's leaderboard row: its family without the scenario, then its seed (merge-dqn-g99/seed-0:
    dqn-g99-seed-0), as zoo/bench_all.sh names it."""
    return f"{run.parent.name.removeprefix(scenario + '-')}-{run.name}"


def _bench(zoo: _Zoo, run: Path, scenario: str) -> list[str]:
    """The model's SHA-256, then its bench row (dense track) and the row's exact check, if the row is of this file."""
    name = row_name(run, scenario)
    digest = sha256(run / "model.zip")
    lines = [f"SHA-256 of `model.zip`: `{digest}`", ""]
    folder = row_folder(zoo.root / "results" / "bench", scenario, name)
    if not (folder / "row.json").is_file():
        return lines + [NO_ROW, ""]
    row = read_row(folder / "row.json")
    if row["key"] != f"sha256:{digest}":  # a row of an earlier model.zip: never shown as this one's
        return lines + [f"The bench row `{zoo.rel(folder / 'row.json')}` is of another model file: bench it again.", ""]
    c = row["clean"]
    path, trust = loader_words(row.get("trust_model", False))
    n, n_clean = row["episodes"], row.get("clean_episodes", row["episodes"])  # version 3: more clean episodes
    attacked = "" if n == n_clean else (f"; on the first {n} episodes, whose clean return is "
                                        f"{row['clean_on_attacked_episodes']['return']:.2f}")
    return lines + [f"Bench row ({row['protocol']}, `{path}zodrive bench {zoo.rel(run)} --scenario {scenario} "
                    f"--name {name}{trust}`): over {n_clean} episodes, clean return {c['return']:.2f} "
                    f"({c['ci95'][0]:.2f}–{c['ci95'][1]:.2f}), {100 * c['collision_rate']:.0f}% collisions, "
                    f"{c['speed']:.1f} m/s; the constant brake {row['brake']['return']:.2f} "
                    f"({100 * row['brake']['collision_rate']:.0f}% collisions). Under the strongest black-box attack "
                    f"inside each ε-ball (docs/bench.md{attacked}): "
                    + ", ".join(
                        f"ε {p['eps']:g} {p['return']:.2f} ({100 * p['collision_rate']:.0f}%)" for p in row["attacked"])
                    + ".", ""] + _exact(row, folder)


def _exact(row: dict[str, Any], folder: Path) -> list[str]:
    """The bench row's exact check (`exact.json`, docs/bench.md "The exact check"), if it is of this row."""
    exact = read_exact(folder)
    if exact is None or why_not_shown({**row, "exact": exact}):
        return []
    n, (first, last) = exact["states"], exact["seeds"]
    return [f"Exact check of the bench row (`{exact['command']}`): of the first {n} clean states (episodes "
            f"{first}–{last}), exactly attackable "
            + ", ".join(f"at ε {p['eps']:g} {p['attackable']}" + (f" ({p['unknown']} unknown)" if p["unknown"] else "")
                        for p in exact["rows"])
            + f"; of those, the black-box ensemble ({', '.join(exact['black_box'])}) missed "
            + ", ".join(f"{p['ensemble']['missed']} of {p['attackable']}" for p in exact["rows"]) + ".", ""]
