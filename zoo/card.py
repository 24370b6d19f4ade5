"""Write the CARD.md of each zoo policy from its own records: the command and seed that trained it
(`train.json`), the checkpoint chosen on tuning seeds (`selection.json`), its SHA-256, and its bench
row (`results/bench/SCENARIO/NAME/row.json`) and its exact check (`exact.json` beside it). Nothing in a card is
typed by hand.

Run: python zoo/card.py
"""

from __future__ import annotations

import json
from pathlib import Path

import yaml
from choose_checkpoint import EPISODES  # zoo/choose_checkpoint.py, beside this script
from q_ensemble import STEPS  # zoo/q_ensemble.py, beside this script
from train import DEFAULTS  # zoo/train.py, beside this script
from zodrive.drivers.baselines import get_baseline
from zodrive.experiments.exact_board import read_exact, why_not_shown
from zodrive.runinfo import sha256

ROOT = Path(__file__).resolve().parents[1]


def card(run: Path) -> str:
    """A DQN trained from scratch by zoo/train.py (a checkpoint chosen on tuning seeds)."""
    train = json.loads((run / "train.json").read_text())
    selection = json.loads((run / "selection.json").read_text())
    scenario = train["scenario"]
    path, trust = loader_words(own_network(train))
    start = selection.get("from_step", 0)  # a choice among the checkpoints after exploration ended
    since, flag = (f" among the checkpoints from step {start:,} on", f" --from-step {start}") if start else ("", "")
    first, last = selection["tuning_seeds"]
    flag += f" --episodes {last - first + 1}" if last - first + 1 != EPISODES else ""
    lines = _trained(run, train) + [
        f"Checkpoint: `{selection['chosen']}`, the best mean return on tuning seeds {first}–{last}{since} "
        f"(`{path}python zoo/choose_checkpoint.py {run.relative_to(ROOT)} --scenario {scenario}{trust}{flag}`), "
        "copied to `model.zip`.", ""]
    return "\n".join(lines + _bench(run, scenario))


def member_card(run: Path, ensembles: list[Path]) -> str:
    """A run trained by zoo/train.py only for its checkpoints' places in ensembles: no checkpoint chosen, no row."""
    names = ", ".join(f"[`{e.parent.name}/{e.name}`](../../{e.parent.name}/{e.name}/CARD.md)" for e in ensembles)
    return "\n".join(_trained(run, json.loads((run / "train.json").read_text())) + [
        f"No checkpoint is chosen and the run is not benched on its own: its checkpoints are members of {names}.", ""])


def _trained(run: Path, train: dict) -> list[str]:
    """The card's title and the command that trained the run."""
    scenario, seed = train["scenario"], train["seed"]
    changed = "".join(f" --{k.replace('_', '-')} {train[k]:g}" if isinstance(v, (int, float))
                      else f" --{k.replace('_', '-')} {train[k]}"
                      for k, v in DEFAULTS.items() if train.get(k, v) != v)  # older runs: defaults
    changed += f" --start-from {train['start_from']}" if "start_from" in train else ""  # a continued run
    changed += " --fast-env" if train.get("fast_env") else ""  # zodrive's copy of the scenario: same weights
    network = (" with the ego-attention network of `zoo/ego_attention.py` (its zips load in zodrive with "
               "`zoo/` on `PYTHONPATH` and `--trust-model`)") if own_network(train) else ""
    return [f"# {run.parent.name} / {run.name}", "",
             f"A DQN for `{scenario}` (highway-env `{train['env_id']}`){network}, trained with plain stable-baselines3 by",
             f"`python zoo/train.py --scenario {scenario} --seed {seed}{changed} --out {run.relative_to(ROOT)}` "
             f"({train['steps']:,} steps{' more, to step ' + format(train['total_steps'], ',') if 'start_from' in train else ''}, "
             f"{train['wall_time_s']:.0f} s).", ""]


def imitation_card(run: Path) -> str:
    """A student cloned by DAgger (`zodrive robust-train --method distill --dagger`): no checkpoint is chosen."""
    train = json.loads((run / "train.json").read_text())
    command = json.loads((run / "run.json").read_text())["command"]
    scenario = yaml.safe_load((run / "config.yaml").read_text())["preset"]["name"]  # the run's own record
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
    return "\n".join(lines + _bench(run, scenario))


ROBUST_KINDS = {"sa-dqn": "SA-DQN's regularizer (Zhang et al., NeurIPS 2020: the Q-values' argmax held over the "
                           "ε-ball, by PGD)",
                "adversarial": "adversarial training (the paper's Algorithm 2: the agent learns from the observations "
                               "its own attacker perturbs, at every step)"}
"""`zodrive robust-train --method sa | at` runs, by the `kind` their train.json records."""


def robust_card(run: Path) -> str:
    """A zoo driver made robust by `zodrive robust-train --method sa|at`: no checkpoint is chosen."""
    train = json.loads((run / "train.json").read_text())
    command = json.loads((run / "run.json").read_text())["command"]
    scenario = yaml.safe_load((run / "config.yaml").read_text())["preset"]["name"]  # the run's own record
    source = Path(train["source_model"]).parent
    lines = [f"# {run.parent.name} / {run.name}", "",
             f"The zoo's [`{source.parent.name}/{source.name}`](../../{source.parent.name}/{source.name}/CARD.md) "
             f"for `{scenario}` made robust by {ROBUST_KINDS[train['kind']]}, {train['total_timesteps']:,} more "
             f"steps (the first {train['warmup_steps']:,} acting only), seed {train['seed']}, "
             f"{train['wall_time_s'] / 60:.0f} min on a shared core:", "",
             f"`{command}`", "",
             "No checkpoint is chosen: the model after the last step is the model.", ""]
    return "\n".join(lines + _bench(run, scenario))


def ensemble_card(run: Path) -> str:
    """An ensemble built by zoo/q_ensemble.py from runs' checkpoints: nothing trained, no checkpoint chosen."""
    build = json.loads((run / "build.json").read_text())
    sources = [Path(r) for r in build["runs"]]
    trains = [json.loads((ROOT / source / "train.json").read_text()) for source in sources]
    scenario = trains[0]["scenario"]
    runs = " and ".join(f"[`{s.parent.name}/{s.name}`](../../{s.parent.name}/{s.name}/CARD.md) (seed {t['seed']})"
                        for s, t in zip(sources, trains, strict=True))
    members = ", ".join(f"`{path}` (`{digest[:12]}…`)" for path, digest in build["members"].items())
    steps = " --steps " + " ".join(map(str, build["steps"])) if tuple(build["steps"]) != STEPS else ""
    k = build.get("pessimism", 0)
    combined = f"the mean less {k:g} standard deviation{'s' * (k != 1)}" if k else "the mean"
    flags = steps + (f" --pessimism {k:g}" if k else "")
    why = "\"An ensemble of a run's last checkpoints\", \"Two runs per seed in one ensemble\"" + (
        ", \"A pessimistic ensemble\"" if k else "")
    lines = [f"# {run.parent.name} / {run.name}", "",
             (f"An ensemble for `{scenario}` (highway-env `{trains[0]['env_id']}`): one stable-baselines3 DQN zip whose "
              f"Q-values are {combined} of the Q-values of {len(build['members'])} checkpoints of the zoo "
              f"run{'s' * (len(sources) > 1)} {runs}: {members}. Nothing is trained and no checkpoint is chosen; it "
              f"is built by `PYTHONPATH=zoo python zoo/q_ensemble.py {' '.join(map(str, sources))} "
              f"{run.relative_to(ROOT)}{flags}`, and loads in zodrive with `zoo/` on `PYTHONPATH` and `--trust-model`. "
              f"Why: `studies/zoo-recipe/README.md`, {why}. A rebuild gives the same weights (`policy.pth`, byte for "
              "byte) in a zip with other bytes: SB3 writes memory addresses into the zip's `data`.")]
    if "from" in build:  # recombined from an earlier ensemble's zip, as the checkpoints are not in the repository
        lines[-1] += (f" This zip was recombined from the members of the ensemble zip with SHA-256 "
                      f"`{build['from_sha256'][:12]}…` (`PYTHONPATH=zoo python zoo/q_ensemble.py --from {build['from']} "
                      f"OUT{flags}`; it was `{build['from']}/model.zip` in the repository's history): its `policy.pth` "
                      "is that zip's, byte for byte.")
    lines.append("")
    return "\n".join(lines + _bench(run, scenario))


def own_network(train: dict) -> bool:
    """A network of its own (not the MLP): zodrive reads its zips with SB3's loader only."""
    return train.get("net", "mlp") != "mlp"


def loader_words(trusted: bool) -> tuple[str, str]:
    """What a command needs before and after itself to load a zoo zip with a network of its own."""
    return ("PYTHONPATH=zoo ", " --trust-model") if trusted else ("", "")


def row_name(run: Path, scenario: str) -> str:
    """The run's leaderboard row: its family without the scenario, then its seed (merge-dqn-g99/seed-0:
    dqn-g99-seed-0), as zoo/bench_all.sh names it."""
    return f"{run.parent.name.removeprefix(scenario + '-')}-{run.name}"


def _bench(run: Path, scenario: str) -> list[str]:
    name = row_name(run, scenario)
    digest = sha256(run / "model.zip")
    lines = [f"SHA-256 of `model.zip`: `{digest}`", ""]
    row_path = ROOT / "results" / "bench" / scenario / name / "row.json"
    if not row_path.is_file():
        return lines + ["No bench row yet: `bash zoo/bench_all.sh`.", ""]
    row = json.loads(row_path.read_text())
    if row["key"] != f"sha256:{digest}":  # a row of an earlier model.zip: never shown as this one's
        return lines + [f"The bench row `{row_path.relative_to(ROOT)}` is of another model file: bench it again.", ""]
    c = row["clean"]
    path, trust = loader_words(row.get("trust_model", False))
    n, n_clean = row["episodes"], row.get("clean_episodes", row["episodes"])  # version 3: more clean episodes
    attacked = "" if n == n_clean else (f"; on the first {n} episodes, whose clean return is "
                                        f"{row['clean_on_attacked_episodes']['return']:.2f}")
    return lines + [f"Bench row ({row['protocol']}, `{path}zodrive bench {run.relative_to(ROOT)} --scenario {scenario} "
                    f"--name {name}{trust}`): over {n_clean} episodes, clean return {c['return']:.2f} "
                    f"({c['ci95'][0]:.2f}–{c['ci95'][1]:.2f}), {100 * c['collision_rate']:.0f}% collisions, "
                    f"{c['speed']:.1f} m/s; the constant brake {row['brake']['return']:.2f} "
                    f"({100 * row['brake']['collision_rate']:.0f}% collisions). Under the strongest black-box attack "
                    f"inside each ε-ball (docs/bench.md{attacked}): "
                    + ", ".join(
                        f"ε {p['eps']:g} {p['return']:.2f} ({100 * p['collision_rate']:.0f}%)" for p in row["attacked"])
                    + ".", ""] + _exact(row, row_path.parent)


def _exact(row: dict, folder: Path) -> list[str]:
    """The bench row's exact check (`exact.json`, docs/bench.md "The exact check"), if it is of this row."""
    exact = read_exact(folder)
    if exact is None or why_not_shown({**row, "exact": exact}):
        return []
    n, first, last = exact["states"], *exact["seeds"]
    return [f"Exact check of the bench row (`{exact['command']}`): of the first {n} clean states (episodes "
            f"{first}–{last}), exactly attackable "
            + ", ".join(f"at ε {p['eps']:g} {p['attackable']}" + (f" ({p['unknown']} unknown)" if p["unknown"] else "")
                        for p in exact["rows"])
            + f"; of those, the black-box ensemble ({', '.join(exact['black_box'])}) missed "
            + ", ".join(f"{p['ensemble']['missed']} of {p['attackable']}" for p in exact["rows"]) + ".", ""]


def cards() -> dict[Path, str]:
    """Every zoo card's path and text, as `main` writes them (nothing is written here)."""
    runs = sorted((ROOT / "models" / "zoo").glob("*/seed-*"))
    members = {}  # run -> the ensembles built from its checkpoints
    for ensemble in (r for r in runs if (r / "build.json").is_file()):
        for source in json.loads((ensemble / "build.json").read_text())["runs"]:
            members.setdefault(ROOT / source, []).append(ensemble)
    texts = {}
    for run in runs:
        if run.parent.name.endswith("-imitation") and (run / "model.zip").is_file():
            texts[run / "CARD.md"] = imitation_card(run)
        elif (run / "train.json").is_file() and json.loads((run / "train.json").read_text()).get("kind") in ROBUST_KINDS:
            texts[run / "CARD.md"] = robust_card(run)
        elif (run / "build.json").is_file():
            texts[run / "CARD.md"] = ensemble_card(run)
        elif (run / "selection.json").is_file():
            texts[run / "CARD.md"] = card(run)
        elif run in members and (run / "train.json").is_file():
            texts[run / "CARD.md"] = member_card(run, members[run])
    return texts


def main() -> None:
    for path, text in cards().items():
        path.write_text(text)
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
