"""The `zodrive` command line. Every user-facing failure is one line on stderr, exit 2."""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import sys
import tempfile
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import yaml

from zodrive.config import MODELS_ENV
from zodrive.defense import DEFENSE_NAMES, parse_defense
from zodrive.errors import ZodriveError
from zodrive.system import build_attacker

log = logging.getLogger("zodrive")


def _int_at_least(least: int, what: str):
    """An argparse type: an integer >= `least`, with a one-line message naming `what`."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if value < least:
            raise argparse.ArgumentTypeError(f"expected {what}, got {value}")
        return value

    return parse


_positive_int = _int_at_least(1, "a positive integer")


def _float_above(least: float, strict: bool, what: str):
    """An argparse type: a finite number above `least` (strictly if `strict`)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if not math.isfinite(value) or value < least or (strict and value == least):
            raise argparse.ArgumentTypeError(f"expected {what}, got {text}")
        return value

    return parse


_positive_float = _float_above(0.0, True, "a finite number > 0")
_nonnegative_float = _float_above(0.0, False, "a finite number >= 0")
_seed = _int_at_least(0, "a seed (an integer >= 0)")
_nonnegative_int = _int_at_least(0, "an integer >= 0")


def _probability_below_one(text: str) -> float:
    """An argparse type: a number in [0, 1)."""
    value = _nonnegative_float(text)
    if value >= 1:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1), got {text}")
    return value


def _bounds(text: str) -> tuple[float, float]:
    """An argparse type: `LOW,HIGH` with LOW < HIGH."""
    try:
        low, high = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LOW,HIGH (two numbers), got {text!r}") from None
    if not low < high:
        raise argparse.ArgumentTypeError(f"expected LOW < HIGH, got {text!r}")
    return low, high


def _envs_flag(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--envs", type=_positive_int, default=None,
                        help="episodes each worker runs side by side, attacked in one call per step; the records "
                             "are the same for every value (default 8; 1 where the policy keeps state or reads "
                             "its simulator)")


def _envs_of(args: argparse.Namespace, *jobs: Any) -> int:
    """`--envs`, or the default; an explicit value above 1 that some job cannot use is an error."""
    from zodrive.evaluation.evaluate import DEFAULT_ENVS, lockstep_blocker

    if args.envs is None:
        return DEFAULT_ENVS
    reasons = [reason for job in jobs if args.envs > 1 and (reason := lockstep_blocker(job))]
    if reasons:
        raise ZodriveError(f"--envs {args.envs}: episodes cannot run side by side here ({reasons[0]}); use --envs 1")
    return args.envs


def _scenario_flags(parser: argparse.ArgumentParser, *, trust: bool = True) -> None:
    """Where a policy drives: a preset or any gymnasium id; and how to read an SB3 zip."""
    parser.add_argument("--preset", help="preset (`zodrive env list`; default: the paper's preset of the model's "
                                         "action kind: discrete or continuous)")
    parser.add_argument("--env-id", metavar="ID",
                        help="any gymnasium environment with a Box observation, instead of --preset")
    parser.add_argument("--obs-bounds", type=_bounds, metavar="LOW,HIGH",
                        help="with --env-id: the range of a clean observation value, when the env does not "
                             "declare one finite interval (the attack's box)")
    parser.add_argument("--env-set", action="append", default=[], metavar="KEY=VALUE", help="preset override")
    if trust:
        parser.add_argument("--trust-model", action="store_true",
                            help="read an SB3 zip with stable-baselines3's own loader, which unpickles it (can run "
                                 "code from the file): for models zodrive cannot rebuild safely")


def _writable_folder(path: Path, flag: str) -> None:
    """Prove that `path` can be a folder we write into, before any work: create it (and its
    parents) and a file in it, then remove what the probe made (no stub is left behind)."""
    if path.exists() and not path.is_dir():
        raise ZodriveError(f"{flag} {path} is a file, not a folder")
    made = [p for p in [path, *path.parents] if not p.exists()]
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError as exc:
        raise ZodriveError(f"{flag} {path}: cannot write there ({exc.strerror or exc})") from None
    finally:
        for folder in made:  # innermost first
            try:
                folder.rmdir()
            except OSError:
                pass


def _check_out(path: Path | None, *, is_file: bool = False) -> None:
    """An --out must be a folder (or a file, for export) that we can create and write to."""
    if path is None:
        return
    if is_file:
        if path.is_dir():
            raise ZodriveError(f"--out {path} is a folder; give the file to write")
        _writable_folder(path.parent if str(path.parent) else Path("."), "--out")
        return
    _writable_folder(path, "--out")


PLOT_SUFFIXES = (".png", ".pdf", ".svg")


def _check_plot(path: Path | None, flag: str = "--plot") -> None:
    """A figure path: an image file (not a folder) in a place we can write, checked before any work."""
    if path is None:
        return
    if path.is_dir() or path.suffix.lower() not in PLOT_SUFFIXES:
        raise ZodriveError(f"{flag} {path}: give an image file ending in {', '.join(PLOT_SUFFIXES)}")
    _writable_folder(path.parent if str(path.parent) else Path("."), flag)


def _refuse_nonempty(path: Path, force: bool, what: str, elsewhere: str = ", or choose another --out") -> None:
    """Nothing is overwritten without --force."""
    if force:
        return
    if path.is_dir() and any(path.iterdir()) or path.is_file():
        raise ZodriveError(f"{path} already holds {what}; use --force to overwrite it{elsewhere}")


class _Help(argparse.ArgumentDefaultsHelpFormatter):
    """Shows a default once: not where the help already states one, nor for None or a flag."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if action.default in (None, False, argparse.SUPPRESS) or action.default == [] or "default" in text \
                or "[" in text:
            return text
        return super()._get_help_string(action) or text


def _defense(text: str) -> str:
    """`--defense`: a known defense, canonical (`shield` -> `shield@0.02`); else a one-line error."""
    try:
        return parse_defense(text)
    except ZodriveError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _defense_or_none(text: str) -> str:
    return "none" if text == "none" else _defense(text)


class _Parser(argparse.ArgumentParser):
    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", _Help)  # --help shows defaults
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> None:  # one line, exit 2, like every other error
        command = self.prog.partition(" ")[2]  # "zodrive evaluate" -> "evaluate"; main adds "zodrive: error:"
        raise ZodriveError(f"{command}: {message}" if command else message)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="zodrive", description="Black-box attacks on deep-RL driving policies.")
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    parser.add_argument("--models", dest="models_dir", type=Path, default=None, metavar="DIR",
                        help="folder of shipped models and their SHA256SUMS (default: $ZODRIVE_MODELS or ./models)")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    env = sub.add_parser("env", help="environment presets")
    env_sub = env.add_subparsers(dest="env_command", required=True, parser_class=_Parser)
    show = env_sub.add_parser("show", help="print a preset's resolved config")
    show.add_argument("preset")
    show.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override (deep merge)")
    env_sub.add_parser("list", help="list the presets, one line each")

    sub.add_parser("baselines", help="list the built-in baseline policies (baseline:NAME)")

    train = sub.add_parser("train", help="train a DQN or DDPG agent")
    train.add_argument("--algo", choices=["dqn", "ddpg", "td3"], required=True)
    train.add_argument("--recipe", help="recipe name or YAML (default: the tuned recipe of --algo)")
    train.add_argument("--seed", type=_seed, help="training seed (default: the recipe's)")
    train.add_argument("--steps", type=_positive_int, help="total timesteps (default: the recipe's budget)")
    train.add_argument("--out", type=Path, required=True, help="run folder")
    train.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="recipe override")
    train.add_argument("--env-set", action="append", default=[], metavar="KEY=VALUE", help="preset override")
    train.add_argument("--tensorboard", action="store_true")
    train.add_argument("--resume", action="store_true", help="continue the run in --out from its newest checkpoint")
    train.add_argument("--force", action="store_true", help="overwrite a run already in --out")
    train.add_argument("--no-progress", action="store_true")

    ev = sub.add_parser("evaluate", help="evaluate a model, clean or under attack")
    ev.add_argument("model", help="SB3 / sb3-contrib zip, model folder, ONNX file, FILE.py:NAME (runs that code) "
                                  "or baseline:NAME (see `zodrive baselines`)")
    _scenario_flags(ev)
    ev.add_argument("--episodes", type=_positive_int, default=100)
    ev.add_argument("--seed", type=_seed, default=None, help="first evaluation seed (default 100000)")
    ev.add_argument("--out", type=Path, help="results folder (summary.json, episodes.jsonl, steps.jsonl)")
    ev.add_argument("--workers", type=_positive_int, default=1)
    _envs_flag(ev)
    ev.add_argument("--defense", type=_defense, metavar="|".join(DEFENSE_NAMES),
                    help="kinematic: filter between the (attacked) sensor and the policy; shield[@EPS]: the "
                         "pessimistic rules at budget EPS (default 0.02) veto unsafe actions; close-shield[@EPS]: the same "
                         "with baseline:close-rules' shorter gap; attacks query the defended system")
    _attack_flags(ev)
    ev.add_argument("--no-progress", action="store_true")

    render = sub.add_parser("render", help="render an episode (PNG + GIF), optionally attacked")
    render.add_argument("model", help="SB3 / sb3-contrib zip, model folder, ONNX file, FILE.py:NAME or baseline:NAME")
    _scenario_flags(render)
    render.add_argument("--seed", type=_seed, default=None, help="first episode seed (default 100000)")
    render.add_argument("--out", type=Path, required=True)
    render.add_argument("--defense", type=_defense, metavar="|".join(DEFENSE_NAMES),
                        help="filter between the (attacked) sensor and the policy; 'perceived' is what passes it")
    render.add_argument("--force", action="store_true", help="overwrite a render already in --out")
    render.add_argument("--until-crash", type=_positive_int, default=1, metavar="N",
                        help="try up to N seeds until an episode ends in a collision")
    _attack_flags(render)

    rob = sub.add_parser("robust-train", help="make a trained agent robust (sa: SA-DQN / SA-DDPG, at: Algorithm 2, distill: robust distillation)")
    rob.add_argument("model")
    rob.add_argument("--method", choices=["sa", "at", "distill"], required=True,
                     help="sa: SA-DQN / SA-DDPG regularizer; at: Algorithm 2; distill: robust distillation of its own (or --teacher's) decisions")
    rob.add_argument("--eps", type=_positive_float,
                     help="L-inf radius the agent is trained to withstand (not with distill --kappa 0: plain cloning)")
    rob.add_argument("--steps", type=_positive_int, required=True, help="training timesteps to add")
    rob.add_argument("--out", type=Path, required=True)
    rob.add_argument("--kappa", type=_nonnegative_float, help="sa, distill: weight of the robustness term "
                                                              "(SA regularizer; distill: the adversarial CE) [0.5]")
    rob.add_argument("--pgd-steps", type=_positive_int, help="sa, distill: PGD steps for the inner max [5]")
    rob.add_argument("--seed", type=_seed, default=1)
    rob.add_argument("--warmup", type=_nonnegative_int, help="sa, at: steps acting before updates start [1000]")
    rob.add_argument("--preset")
    rob.add_argument("--env-set", action="append", default=[], metavar="KEY=VALUE")
    rob.add_argument("--force", action="store_true")
    rob.add_argument("--trust-model", action="store_true")
    rob.add_argument("--epochs", type=_positive_int, help="distill: passes over the collected states [20]")
    rob.add_argument("--teacher", metavar="baseline:NAME",
                     help="distill: an observation-reading baseline that drives and labels (default: the model itself); "
                          "with --dagger also the simulator-reading baseline:idm-mobil (a DDPG/TD3 actor's teacher) or "
                          "baseline:planner (a DQN's)")
    rob.add_argument("--dagger", type=_nonnegative_int, metavar="ROUNDS",
                     help="distill: behaviour cloning with DAgger (Ross et al. 2011): after the teacher's --steps states, "
                          "ROUNDS rounds of --steps states the student drives into (a DDPG/TD3 student: with the "
                          "teacher's action with probability 0.5 ** round), labelled by the teacher; "
                          "--epochs per refit")
    rob.add_argument("--no-progress", action="store_true")

    exp = sub.add_parser("export", help="write a model's acting network as ONNX (a victim format with no pickle)")
    exp.add_argument("model", help="SB3 zip or model folder")
    exp.add_argument("--format", choices=["onnx"], default="onnx")
    exp.add_argument("--out", type=Path, required=True, help="the .onnx file to write")
    exp.add_argument("--force", action="store_true", help="overwrite an existing --out file")

    sel = sub.add_parser("select", help="pick a training run's best checkpoint on tuning seeds (never evaluation seeds)")
    sel.add_argument("run", type=Path, help="training run folder (with checkpoints/)")
    sel.add_argument("--episodes", type=_positive_int, default=20, help="tuning episodes per checkpoint")
    sel.add_argument("--from-step", type=_nonnegative_int, default=0, help="ignore checkpoints before this step")
    sel.add_argument("--workers", type=_positive_int, default=1)
    sel.add_argument("--force", action="store_true", help="replace a selection already in RUN/selected.json")
    sel.add_argument("--no-progress", action="store_true")

    adv = sub.add_parser("adv-train", help="adversarial training (paper Algorithm 2)")
    adv.add_argument("model")
    adv.add_argument("--attack", help="attack config name/YAML or registry name [zo-signsgd]")
    adv.add_argument("--no-attack", action="store_true",
                     help="the control run: the same continued training on clean observations")
    adv.add_argument("--attack-set", action="append", default=[], metavar="KEY=VALUE",
                     help="attack override, e.g. steps=50 (T) or eps=0.1")
    adv.add_argument("--steps", type=_positive_int, required=True, help="training timesteps to add")
    adv.add_argument("--out", type=Path, required=True)
    adv.add_argument("--preset")
    adv.add_argument("--env-set", action="append", default=[], metavar="KEY=VALUE")
    adv.add_argument("--seed", type=_seed, default=1, help="seed of the adversarial phase")
    adv.add_argument("--warmup", type=_nonnegative_int, default=1000,
                     help="steps the (attacked) policy acts to fill the empty replay buffer before updates start; "
                          "0 = update from the first step (degrades the policy even without attack)")
    adv.add_argument("--force", action="store_true", help="overwrite a run already in --out")
    adv.add_argument("--trust-model", action="store_true",
                     help="load MODEL with stable-baselines3's full loader, which unpickles it (can run code "
                          "from the file); needed for any model but the shipped ones")
    adv.add_argument("--no-progress", action="store_true")

    atk = sub.add_parser("attack-train", help="train a learned optimal adversary (SA-RL, Zhang et al. ICLR 2021) "
                                              "against a model; use it with --attack learned:DIR")
    atk.add_argument("model", help="SB3 zip or model folder: the victim (fixed)")
    atk.add_argument("--eps", type=_positive_float, required=True, help="L-inf radius of the perturbation")
    atk.add_argument("--steps", type=_nonnegative_int, required=True,
                     help="environment steps of PPO training (0: the fitted start of --pretrain-rounds alone)")
    atk.add_argument("--pretrain-rounds", type=_positive_int,
                     help="first fit the adversary as an amortized transfer attack: rounds of driving under it, "
                          "distilling a surrogate from counted victim queries, fitting the mean action to make the "
                          "surrogate take the target action (zodrive.training.amortized)")
    atk.add_argument("--pretrain-episodes", type=_positive_int, help="episodes driven per round (default 10)")
    atk.add_argument("--pretrain-probe", choices=("ball", "vertices"),  # amortized.PROBES (torch-free here)
                     help="where the surrogate's random queries are drawn around each visited state: uniformly in "
                          "the eps-ball (default) or on its vertices, half near the adversary's own")
    atk.add_argument("--pretrain-loss", choices=("scores", "decisions"),  # amortized.LOSSES
                     help="the surrogate's fit: MSE on the victim's scores (default), or, for a discrete victim, that "
                          "plus cross-entropy on its chosen action")
    atk.add_argument("--pretrain-probes", type=_nonnegative_int,
                     help="random eps-ball points queried per visited state for the surrogate (default 4)")
    atk.add_argument("--pretrain-margin", type=_nonnegative_float,
                     help="the target action must win on the surrogate by this many of the victim's median decision "
                          "gaps (default 1)")
    atk.add_argument("--target", default="auto", help="with --pretrain-rounds: the per-step target the start is fitted to, as "
                                       "evaluate's --target (default auto: FASTER / '1,0.5'); e.g. FASTER,not:SLOWER")
    atk.add_argument("--explore-std", type=_positive_float,
                     help="PPO's exploration: a Gaussian of this std per action dimension (in units of eps), "
                          "redrawn every step, instead of the default gSDE noise (whose std on the highway "
                          "presets is about 1.3-1.9: the eps-box's corners, whatever the mean)")
    atk.add_argument("--critic-warmup", type=_positive_int,
                     help="the first N of --steps train PPO's value function only, the actor frozen (keeps a "
                          "fitted start while the critic learns its returns)")
    atk.add_argument("--out", type=Path, required=True, help="the adversary's model folder")
    atk.add_argument("--seed", type=_seed, default=0, help="training seed (PPO and the environment)")
    atk.add_argument("--defense", type=_defense, metavar="shield[@EPS]|close-shield[@EPS]",
                     help="train against the defended system (stateless defenses only)")
    atk.add_argument("--victim-action", action="store_true",
                     help="the adversary also observes the victim's clean action (1 query per step at attack time)")
    atk.add_argument("--reward", choices=["minus", "horizon"], default="minus",
                     help="minus: -(victim's reward); horizon: 1 - reward per step and the steps a crash cuts off "
                          "at once (the same objective, credited when the crash happens)")
    _scenario_flags(atk, trust=False)
    atk.add_argument("--force", action="store_true", help="overwrite an adversary already in --out")
    atk.add_argument("--no-progress", action="store_true")

    pick = sub.add_parser("picker-train", help="fit a picker for vertex hold from counted victim queries: which "
                                                "random vertex to feed; use it with --attack vertex-hold:DIR or vertex-check:DIR")
    from zodrive.training.picker import LOSSES, PickerFit  # torch-free

    pick.add_argument("model", help="SB3 zip or model folder: the victim (fixed)")
    pick.add_argument("--eps", type=_positive_float, required=True, help="L-inf radius of the perturbation")
    pick.add_argument("--out", type=Path, required=True, help="the picker's folder")
    pick.add_argument("--seed", type=_seed, default=0, help="fit seed: training episodes 10000*seed + 1000*round + i")
    pick.add_argument("--target", default="auto", help="what the picker rates vertices for, as evaluate's --target: "
                                                       "auto (FASTER / '1,0.5'), an action name or index, or not:ACTION")
    for flag, kind, what in (("rounds", _positive_int, "rounds of driving under vertex hold, querying, refitting"),
                             ("episodes", _positive_int, "training episodes driven per round"),
                             ("probes", _positive_int, "random vertices queried at every state met"),
                             ("epochs", _positive_int, "passes over the labelled vertices per round"),
                             ("width", _positive_int, "hidden units of each of the MLP's two layers"),
                             ("candidates", _positive_int, "random vertices ranked at attack time when one is needed"),
                             ("switch", _probability_below_one, "a held vertex the picker rates below this is replaced "
                                                                "(0: never)")):
        pick.add_argument(f"--{flag}", type=kind, help=f"{what} [{getattr(PickerFit, flag)}]")
    pick.add_argument("--loss", choices=LOSSES, help="bce: each vertex's label alone; rank: also the order of the "
                                                     f"vertices within each state [{PickerFit.loss}]")
    _scenario_flags(pick, trust=False)
    pick.add_argument("--force", action="store_true", help="overwrite a picker already in --out")

    rep = sub.add_parser("reproduce", help="the paper's Table 1, figures and a report, in one command")
    rep.add_argument("--out", type=Path, required=True)
    rep.add_argument("--episodes", type=_positive_int, help="episodes per cell [100]")
    rep.add_argument("--workers", type=_positive_int, default=2)
    _envs_flag(rep)
    rep.add_argument("--quick", action="store_true", help="5 episodes per cell (a smoke run, minutes); not with --episodes")
    rep.add_argument("--retrain", action="store_true", help="train all four models anew instead of the shipped ones")
    rep.add_argument("--robustness-episodes", type=_nonnegative_int, default=10,
                     help="episodes per cell of the robustness section (0: leave it out)")
    rep.add_argument("--no-progress", action="store_true")
    _backend_flags(rep)

    cmp_ = sub.add_parser("compare", help="table of attacks x eps x models (each cell an evaluation)")
    cmp_.add_argument("models", nargs="+", help="SB3 zips, model folders or baseline:NAME")
    cmp_.add_argument("--attacks", nargs="+", default=None,
                      help="default: every registered attack that takes the --attack-set options (the others are named)")
    cmp_.add_argument("--eps", nargs="+", type=float, default=[0.2])
    cmp_.add_argument("--query-budgets", nargs="+", type=_positive_int, default=None,
                      help="per-step query budgets, one cell each (default: no cap)")
    _scenario_flags(cmp_, trust=False)  # applied to every model
    cmp_.add_argument("--attack-set", action="append", default=[], metavar="KEY=VALUE",
                      help="attack option for every attack of the grid, e.g. patience=10")
    cmp_.add_argument("--defense", nargs="+", default=None, type=_defense_or_none,
                      metavar="none|" + "|".join(DEFENSE_NAMES),
                      help="defenses in front of each model, one set of cells each (none = undefended)")
    cmp_.add_argument("--plot", type=Path, default=None,
                      help="PNG: with --query-budgets, return and success against queries per step; "
                           "otherwise return against eps under the strongest attack")
    _backend_flags(cmp_)
    cmp_.add_argument("--episodes", type=_positive_int, default=20)
    cmp_.add_argument("--workers", type=_positive_int, default=1)
    _envs_flag(cmp_)
    cmp_.add_argument("--out", type=Path, required=True)
    cmp_.add_argument("--force", action="store_true", help="replace the tables of another comparison in --out")
    cmp_.add_argument("--no-progress", action="store_true")

    demo = sub.add_parser("demo", help="attack the shipped DQN driver for a few episodes and print the result")
    demo.add_argument("--episodes", type=_positive_int, default=3, help="episodes, clean and attacked")
    demo.add_argument("--model", default=None, help="model folder or zip; None = the DQN shipped inside the package")
    demo.add_argument("--out", type=Path, default=Path("results/demo"), help="results folder")

    cert = sub.add_parser("certify", help="share of a model's clean states where no perturbation within eps can "
                                          "change the action (interval bounds; reads the weights: white-box)")
    cert.add_argument("model", help="SB3 / sb3-contrib zip or model folder (MLP policies)")
    cert.add_argument("--eps", nargs="+", type=_positive_float, required=True, help="L-inf radii to certify")
    _scenario_flags(cert, trust=False)
    cert.add_argument("--episodes", type=_positive_int, default=5, help="clean episodes whose states are certified")
    cert.add_argument("--seed", type=_seed, default=None, help="first episode seed (default 100000)")
    cert.add_argument("--tol", type=_positive_float,
                      help="continuous policies: a state counts as certified if no action dimension can move more [0.2]")
    cert.add_argument("--attack", nargs="+", default=[], metavar="NAME",
                      help="also attack every one of those states on its own (untargeted) with these attacks: their "
                           "success beside the certified share; the gap between them is unknown")
    cert.add_argument("--out", type=Path, help="folder for certify.json")
    cert.add_argument("--force", action="store_true", help="overwrite certify.json in --out")

    curves = sub.add_parser("curves", help="learning curves of training runs side by side (table, --plot PNG)")
    curves.add_argument("runs", nargs="+", type=Path, help="run folders (with monitor.monitor.csv)")
    curves.add_argument("--bin", type=_positive_int, default=20000, help="steps per window")
    curves.add_argument("--plot", type=Path, help="also draw the curves to this PNG")
    curves.add_argument("--force", action="store_true", help="overwrite an existing --plot file")

    card = sub.add_parser("card", help="write CARD.md for a trained model folder")
    card.add_argument("folder", type=Path, help="run folder (model.zip, run.json, train.json, eval/)")
    card.add_argument("--baseline", type=Path, help="evaluation folder of the SB3-defaults recipe, for comparison")
    card.add_argument("--eval", type=Path, help="evaluation folder to report (default FOLDER/eval)")
    card.add_argument("--note", action="append", default=[], help="a line for the card's Notes section")
    card.add_argument("--seeds", nargs="+", type=Path, default=None, metavar="RUN",
                      help="run folders of every training seed (each with eval/): median and range in the card")
    card.add_argument("--attacked", nargs="+", type=Path, default=None, metavar="EVAL",
                      help="evaluation folders of the model under attack, listed in the card")
    card.add_argument("--force", action="store_true",
                      help="replace an existing CARD.md (hand-written sections in it are lost)")
    return parser


def _backend_flags(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--backend", choices=["local", "ray"], default="local",
                        help="where cells run: this process (episodes over --workers) or Ray tasks (cells in parallel)")
    parser.add_argument("--address", default=None,
                        help="Ray cluster address (default: a local Ray instance with --workers CPUs)")


def _attack_flags(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("attack (black-box unless the name says otherwise)")
    group.add_argument("--attack", help="attack config name/YAML, registry name, learned:DIR (an adversary "
                                        "trained by attack-train), vertex-hold:DIR or vertex-check:DIR (a picker fitted by picker-train)")
    group.add_argument("--eps", type=float)
    group.add_argument("--norm", choices=["linf", "l2"])
    group.add_argument("--mode", choices=["budgeted", "paper"])
    group.add_argument("--steps", type=int, help="T, iterations per environment step")
    group.add_argument("--n-directions", type=int, help="q, directions per iteration")
    group.add_argument("--mu", type=float)
    group.add_argument("--step-size", type=float)
    group.add_argument("--l2-weight", type=float)
    group.add_argument("--target", help="FASTER, an action index, '1,0.5', auto, none (untargeted), worst, "
                                        "not:ACTION (discrete: any action but that one, e.g. not:SLOWER) or "
                                        "ACTION,not:ACTION (the action, else at least not the other: FASTER,not:SLOWER)")
    group.add_argument("--loss", choices=["margin", "paper"])
    group.add_argument("--query-budget", type=int, help="max queries per environment step")
    group.add_argument("--early-stop", dest="early_stop", action="store_true", default=None)
    group.add_argument("--no-early-stop", dest="early_stop", action="store_false")
    group.add_argument("--patience", type=_positive_int, help="give up a step after N iterations without progress")
    group.add_argument("--no-patience", action="store_true", default=None,
                       help="run every step until its goal is met or T iterations are spent")
    group.add_argument("--warm-start", dest="warm_start", action="store_true", default=None,
                       help="start each step's search from the previous step's perturbation")
    group.add_argument("--no-warm-start", dest="warm_start", action="store_false",
                       help="start each step's search at the clean observation")
    group.add_argument("--on-failure", choices=["best", "clean"],
                       help="what a step that missed the goal feeds the policy")
    group.add_argument("--restarts", type=_nonnegative_int, help="further runs from random points (e.g. PGD)")
    group.add_argument("--timing", type=float,
                       help="strategically timed attack: only steps where the policy's action preference >= this (0-1)")
    group.add_argument("--episode-query-budget", type=_positive_int, help="max queries per episode")
    group.add_argument("--max-change", type=float,
                       help="defense-aware attacker: the perturbation changes by at most this (L-inf) between steps")
    group.add_argument("--access", choices=["score", "decision"],
                       help="what the attacker's queries return: scores (Q-values/action) or only the decision")
    group.add_argument("--check-below", type=float,
                       help="vertex-check:DIR: a held vertex the picker rates at least this (0-1) is fed without a check; "
                            "the saved queries pay for checks of fresh vertices (at most 1 query per step on average)")
    group.add_argument("--attack-seed", type=_seed)


ATTACK_FLAGS = {"--eps": "eps", "--norm": "norm", "--mode": "mode", "--steps": "steps",
                "--n-directions": "n_directions", "--mu": "mu", "--step-size": "step_size",
                "--l2-weight": "l2_weight", "--target": "target", "--loss": "loss",
                "--query-budget": "query_budget", "--early-stop/--no-early-stop": "early_stop",
                "--patience": "patience", "--no-patience": "no_patience", "--warm-start/--no-warm-start": "warm_start",
                "--on-failure": "on_failure", "--restarts": "restarts",
                "--timing": "timing", "--episode-query-budget": "episode_query_budget", "--access": "access",
                "--max-change": "max_change", "--check-below": "check_below",
                "--attack-seed": "attack_seed"}


def attack_spec_from_args(args: argparse.Namespace):
    """The AttackSpec named by --attack with the CLI's flags on top (None without --attack)."""
    from zodrive.attacks.spec import load_attack

    if not args.attack:
        given = [flag for flag, dest in ATTACK_FLAGS.items() if getattr(args, dest, None) is not None]
        if given:
            raise ZodriveError(f"{', '.join(given)} set an attack's options, but no --attack was given")
        return None
    if args.patience is not None and args.no_patience:
        raise ZodriveError("--patience N and --no-patience contradict each other: give one")
    # flags are named after AttackSpec fields; --attack-seed sets the spec's `seed`
    spec = load_attack(args.attack).with_overrides(
        **{("seed" if dest == "attack_seed" else dest): getattr(args, dest) for dest in ATTACK_FLAGS.values()
           if dest != "no_patience"})
    return spec.with_overrides(clear=["patience"]) if args.no_patience else spec


def cmd_env(args: argparse.Namespace) -> int:
    from zodrive.envs import load_preset, preset_names

    if args.env_command == "list":
        from zodrive.envs import preset_summary

        names = preset_names()
        width = max(map(len, names))
        for name in names:
            print(f"{name:{width}}  {preset_summary(name)}")
        print("any other gymnasium environment with a Box observation: --env-id ID [--obs-bounds LOW,HIGH]")
        return 0
    print(yaml.safe_dump(load_preset(args.preset, args.set), sort_keys=False), end="")
    return 0


def cmd_baselines(args: argparse.Namespace) -> int:
    from zodrive.drivers.baselines import BASELINES, PREFIX

    for b in BASELINES.values():
        print(f"{PREFIX + b.name:22} {'/'.join(b.kinds):20} reads {b.reads:10} {b.description}")
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    from zodrive.training.recipes import load_recipe, train

    if args.resume and args.force:
        raise ZodriveError("--resume continues the run in --out, --force replaces it: give one of them")
    overrides = list(args.set)
    if args.steps:
        overrides.append(f"total_timesteps={args.steps}")
    recipe = load_recipe(args.recipe or args.algo, overrides)
    if recipe["algo"] != args.algo:
        raise ZodriveError(f"recipe {args.recipe!r} trains {recipe['algo']}, not {args.algo}")
    path = train(recipe, args.out, seed=args.seed, preset_overrides=args.env_set,
                 progress_bar=not args.no_progress, tensorboard=args.tensorboard,
                 resume=args.resume, force=args.force)
    print(f"saved {path}")
    return 0


def _preset_of(args: argparse.Namespace) -> dict[str, Any]:
    """Where `args.model` drives: --preset, --env-id (with --obs-bounds) or its action kind's preset."""
    from zodrive.policies.resolve import resolve_preset

    return resolve_preset(args.model, args.preset, args.env_set, getattr(args, "env_id", None),
                          getattr(args, "obs_bounds", None))


def _check_trust(args: argparse.Namespace) -> None:
    """--trust-model reads SB3 zips; for anything else it would be ignored: an error."""
    if getattr(args, "trust_model", False):
        from zodrive.policies.resolve import is_sb3_zip

        if not is_sb3_zip(str(args.model)):
            raise ZodriveError("--trust-model applies to stable-baselines3 zips; this model is read without it")


def _check_loss(args: argparse.Namespace, spec: Any, preset: dict[str, Any]) -> None:
    """--loss chooses between the DQN objectives of a targeted attack; elsewhere it does nothing."""
    if spec is None or getattr(args, "loss", None) is None:
        return
    from zodrive.envs import action_kind

    if action_kind(preset) != "discrete":
        raise ZodriveError("--loss chooses the objective of a targeted attack on a discrete policy; this policy "
                           "acts continuously (its objective is the paper's Eq. 6)")
    if str(spec.target).lower() in ("none", "untargeted", "worst"):
        raise ZodriveError("--loss chooses the objective of a targeted attack on a discrete policy; "
                           f"target {spec.target} has no such choice")


def cmd_evaluate(args: argparse.Namespace) -> int:
    from zodrive.policies.resolve import check_policy, load_victim, policy_ref
    from zodrive.evaluation.evaluate import DEFAULT_EVAL_SEED, EvalJob, evaluate
    from zodrive.evaluation.report import format_summary

    spec = attack_spec_from_args(args)  # argument mistakes first, before any model is read
    preset = _preset_of(args)
    _check_trust(args)
    _check_loss(args, spec, preset)
    check_policy(args.model, preset, attacked=spec is not None)
    if spec is not None:  # validate the whole attack before any episode runs

        build_attacker(spec, load_victim(args.model, preset, trust=args.trust_model), preset)
    if args.defense is not None:
        from zodrive.defense import make_defense

        make_defense(args.defense, preset)  # the preset must be one the defense understands
    job = EvalJob(
        model=policy_ref(args.model), preset=preset,
        attack=spec.to_dict() if spec else None,
        seed=DEFAULT_EVAL_SEED if args.seed is None else args.seed, defense=args.defense, trust=args.trust_model,
    )
    summary = evaluate(job, args.episodes, args.out, workers=args.workers, envs=_envs_of(args, job),
                       progress=not args.no_progress)
    print(format_summary(summary))
    if args.out:
        print(f"results: {args.out}/summary.json")
    return 0


def cmd_render(args: argparse.Namespace) -> int:
    from zodrive.policies.resolve import policy_ref
    from zodrive.system import make_policy_env
    from zodrive.evaluation.evaluate import DEFAULT_EVAL_SEED
    from zodrive.evaluation.video import record_episode, save_gif, save_mp4, save_png

    spec = attack_spec_from_args(args)
    _refuse_nonempty(args.out, args.force, "a render")
    preset = _preset_of(args)
    _check_trust(args)
    _check_loss(args, spec, preset)
    if spec is not None:
        from zodrive.evaluation.evaluate import check_trained_folder

        check_trained_folder(spec.to_dict(), policy_ref(str(args.model)), preset, args.defense)
    victim, env = make_policy_env(args.model, preset, spec, render_mode="rgb_array", defense=args.defense,
                                  trust=args.trust_model)
    first = DEFAULT_EVAL_SEED if args.seed is None else args.seed
    for seed in range(first, first + args.until_crash):
        frames, info = record_episode(env, victim, seed)
        if info["crashed"]:
            break
    if float(np.asarray(frames[0].image).max()) == 0:
        raise ZodriveError("rendered frames are black: unset SDL_VIDEODRIVER or set it to 'offscreen'")
    title = (f"{spec.attack} eps={spec.eps} | " if spec else "clean | ") + (f"+{args.defense} | " if args.defense else "")
    save_png(frames, args.out / "episode.png", title=title)
    save_gif(frames, args.out / "episode.gif", title=title)
    mp4 = save_mp4(frames, args.out / "episode.mp4", title=title)
    from zodrive.runinfo import write_json

    write_json(args.out / "episode.json", {**info, "attack": spec.to_dict() if spec else None, "defense": args.defense})
    print(f"seed {info['seed']}: return {info['return']:.2f}, {info['length']} steps, "
          f"{'crashed' if info['crashed'] else 'left the road' if info['offroad'] else 'no collision'}"
          f" -> {args.out}/episode.png, episode.gif" + (", episode.mp4" if mp4 else " (MP4: pip install 'zodrive[video]')"))
    return 0


def cmd_adv_train(args: argparse.Namespace) -> int:
    from zodrive.attacks.spec import load_attack
    from zodrive.training.adversarial import adversarial_train

    preset = _preset_of(args)
    if args.no_attack and (args.attack_set or args.attack):
        raise ZodriveError(f"{'--attack-set' if args.attack_set else '--attack'} has no effect with --no-attack")
    spec = None if args.no_attack else load_attack(args.attack or "zo-signsgd", args.attack_set)
    path = adversarial_train(args.model, preset, spec, args.steps, args.out, seed=args.seed,
                             warmup=args.warmup, progress_bar=not args.no_progress, trust=args.trust_model,
                             force=args.force)
    print(f"saved {path}")
    return 0


def cmd_attack_train(args: argparse.Namespace) -> int:
    from zodrive.training.adversary import attack_train
    from zodrive.training.amortized import Pretrain, surrogate_fit

    preset = _preset_of(args)
    given = {name: value for name, value in (("episodes", args.pretrain_episodes), ("margin", args.pretrain_margin),
                                            ("probe", args.pretrain_probe), ("probes", args.pretrain_probes),
                                            ("loss", args.pretrain_loss))
             if value is not None}
    pretrain = Pretrain(rounds=args.pretrain_rounds, **given) if args.pretrain_rounds else None
    if pretrain is None and given:
        raise ZodriveError(f"--pretrain-{next(iter(given))} applies with --pretrain-rounds")
    if pretrain is None and args.steps == 0:
        raise ZodriveError("--steps 0 trains nothing: give PPO steps, or a fitted start with --pretrain-rounds")
    path = attack_train(str(args.model), preset, args.eps, args.steps, args.out, seed=args.seed, defense=args.defense,
                        victim_action=args.victim_action, reward=args.reward, pretrain=pretrain,
                        target=args.target, explore_std=args.explore_std,
                        critic_warmup=args.critic_warmup or 0, force=args.force, progress_bar=not args.no_progress)
    train = json.loads((path / "train.json").read_text())
    for r in (train["pretrain"] or {}).get("rounds", []):
        print(f"pretrain round {r['round']}: {r['steps']} steps, victim return {r['victim_return']:.2f}, target action "
              f"on {r['target_share']:.1%} of steps, {r['queries']} queries so far, {surrogate_fit(r)}; fitted: "
              f"target on the surrogate on {r['surrogate_target_share']:.1%} of visited states")
    if train["total_timesteps"]:
        print(f"{train['total_timesteps']} steps, {train['episodes']} episodes in {train['wall_time_s']} s; victim "
              f"queries {train['victim_queries']} ({train['queries_per_step']:.2f}/step); victim return over the "
              f"first / last 10 training episodes: {train['victim_return_first10']} / {train['victim_return_last10']}")
    print(f"saved {path} (use: --attack learned:{path} --eps {args.eps:g})")
    return 0


def cmd_picker_train(args: argparse.Namespace) -> int:
    from dataclasses import fields, replace

    from zodrive.training.picker import PickerFit, picker_train

    given = {f.name: getattr(args, f.name) for f in fields(PickerFit) if getattr(args, f.name) is not None}
    path = picker_train(str(args.model), _preset_of(args), args.eps, args.out, replace(PickerFit(), **given),
                        seed=args.seed, target=args.target, force=args.force, report=lambda line: print(line, flush=True))
    scenario = "".join([f" --preset {args.preset}" if args.preset else "",
                        *(f" --env-set {item}" for item in args.env_set),
                        f" --env-id {args.env_id}" if args.env_id else "",
                        f" --obs-bounds {args.obs_bounds[0]:g},{args.obs_bounds[1]:g}" if args.obs_bounds else ""])
    target = "" if args.target == "auto" else f" --target {args.target}"
    print(f"saved {path} (use: --attack vertex-hold:{path} --eps {args.eps:g}{target}{scenario})")
    return 0


def cmd_robust_train(args: argparse.Namespace) -> int:
    from zodrive.training.robust import robust_train

    uses = {"sa": {"kappa", "pgd_steps", "warmup", "trust_model"}, "at": {"warmup", "trust_model"},
            "distill": {"kappa", "pgd_steps", "epochs", "teacher", "dagger"}}[args.method]
    for option in ("kappa", "pgd_steps", "warmup", "epochs", "teacher", "trust_model", "dagger"):
        if getattr(args, option) not in (None, False) and option not in uses:
            raise ZodriveError(f"--{option.replace('_', '-')} has no effect with --method {args.method}")
    kappa = 0.5 if args.kappa is None else args.kappa
    if args.method == "distill" and kappa == 0 and (args.eps is not None or args.pgd_steps is not None):
        raise ZodriveError(f"--{'eps' if args.eps is not None else 'pgd-steps'} has no effect with --kappa 0 "
                           "(plain cloning: no adversarial term)")
    preset = _preset_of(args)
    path = robust_train(args.model, preset, args.method, args.eps, args.steps, args.out, seed=args.seed,
                        warmup=1000 if args.warmup is None else args.warmup, kappa=kappa,
                        pgd_steps=args.pgd_steps or 5, progress_bar=not args.no_progress, trust=args.trust_model,
                        force=args.force, teacher=args.teacher, epochs=args.epochs or 20, dagger=args.dagger)
    print(f"saved {path}")
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    from zodrive.policies.onnx_policy import export_onnx

    _refuse_nonempty(args.out, args.force, "a file")
    print(f"wrote {export_onnx(args.model, args.out)}")
    return 0


def cmd_select(args: argparse.Namespace) -> int:
    from zodrive.experiments.select import select_checkpoint, selection_markdown

    _refuse_nonempty(args.run / "selected.json", args.force, "a selection", "")
    choice = select_checkpoint(args.run, args.episodes, from_step=args.from_step, workers=args.workers,
                               progress=not args.no_progress)
    print(selection_markdown(choice), end="")
    print(f"selected: {choice['selected']['model']} ({choice['criterion']}); written to {args.run / 'selected.json'}")
    return 0


def cmd_reproduce(args: argparse.Namespace) -> int:
    from zodrive.experiments.report import table_markdown
    from zodrive.experiments.reproduce import reproduce

    if args.quick and args.episodes is not None:
        raise ZodriveError("--quick runs 5 episodes per cell; --episodes would be ignored: give one of them")
    table = reproduce(args.out, episodes=args.episodes or 100, workers=args.workers, quick=args.quick,
                      robustness_episodes=args.robustness_episodes,
                      retrain=args.retrain, progress=not args.no_progress, backend=args.backend, address=args.address,
                      envs=_envs_of(args))
    print(table_markdown(table["rows"]), end="")
    print(f"report: {args.out}/report.html")
    return 0


def cmd_compare(args: argparse.Namespace) -> int:
    from zodrive.experiments.compare import compare, default_attacks, markdown, plot_budget_curves, plot_robustness

    defenses = [None if d == "none" else d for d in args.defense or ["none"]]
    attacks = args.attacks
    if not attacks:  # every attack that takes the --attack-set options; the others are named
        attacks, left_out = default_attacks(args.attack_set)
        for name, why in left_out.items():
            print(f"({name} left out of the default attacks: {why})", file=sys.stderr)
    rows = compare(args.models, attacks, args.eps, args.episodes, args.out,
                   workers=args.workers, progress=not args.no_progress, query_budgets=args.query_budgets,
                   backend=args.backend, address=args.address, defenses=defenses, env_set=args.env_set,
                   attack_set=args.attack_set, preset=args.preset, env_id=args.env_id, obs_bounds=args.obs_bounds,
                   force=args.force, envs=_envs_of(args))
    print(markdown(rows), end="")
    if args.plot:
        (plot_budget_curves if args.query_budgets else plot_robustness)(rows, args.plot)
        print(f"plot: {args.plot}")
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    from zodrive.policies.resolve import policy_label, policy_ref
    from zodrive.attacks.spec import load_attack
    from zodrive.evaluation.evaluate import DEFAULT_EVAL_SEED, EvalJob, evaluate
    from zodrive.evaluation.report import format_summary, plural
    from zodrive.config import demo_model

    model = args.model or str(demo_model())
    from zodrive.policies.resolve import resolve_preset

    preset = resolve_preset(model, None, [])
    ref, name = policy_ref(model), ("the shipped DQN driver (models/dqn-driver)" if args.model is None else policy_label(model))
    spec = load_attack("zo-signsgd")
    results = {}
    for label, attack in (("clean", None), ("attacked", spec)):
        job = EvalJob(model=ref, preset=preset, attack=attack.to_dict() if attack else None, seed=DEFAULT_EVAL_SEED)
        print(f"== {label}: {plural(args.episodes, 'episode')} of {name}" + (f" under {spec.attack}" if attack else ""))
        results[label] = evaluate(job, args.episodes, args.out / label, progress=True)
        print(format_summary(results[label]))
    drop = 1 - results["attacked"]["mean_return"] / results["clean"]["mean_return"]
    print(f"== the black-box attack (L-inf eps={spec.eps}) cut the mean return by {drop:.0%} "
          f"({results['clean']['mean_return']:.1f} -> {results['attacked']['mean_return']:.1f}); "
          f"results in {args.out}/")
    print("   target=auto: the paper's target action (FASTER for a DQN, [1, 0.5] for a DDPG).")
    print("   base rate: how often the clean policy already takes the target; success counts only the other steps.")
    print("   queries/step: observations the attacker sent to the policy per decision (black-box cost).")
    return 0


def cmd_certify(args: argparse.Namespace) -> int:
    from zodrive.attacks.registry import ATTACKS
    from zodrive.policies.loading import model_kind
    from zodrive.policies.resolve import is_sb3_zip
    from zodrive.attacks.spec import load_attack
    from zodrive.evaluation.certify import certify_model
    from zodrive.evaluation.evaluate import DEFAULT_EVAL_SEED
    from zodrive.runinfo import command_line, write_json

    model = str(args.model)
    if not is_sb3_zip(model):
        raise ZodriveError("certify bounds an SB3 zip's rebuilt network; baselines, ONNX files and Python "
                           "policies have no network zodrive can read")
    if args.out is not None:
        _refuse_nonempty(args.out / "certify.json", args.force, "certificates")
    preset = _preset_of(args)
    if args.tol is not None and model_kind(model) == "discrete":
        raise ZodriveError("--tol applies to continuous policies; a discrete one is certified when its action cannot change")
    tol = 0.2 if args.tol is None else args.tol
    for name in args.attack:
        spec = load_attack(name)  # an unknown attack is an error before any episode runs
        if spec.attack not in ATTACKS or not ATTACKS[spec.attack].search:
            raise ZodriveError(f"certify attacks every state on its own, untargeted, beside its certificate: "
                               f"{spec.attack} is no per-state search (use random-search, zo-signsgd, pgd, ...)")
    result = certify_model(model, preset, args.eps, episodes=args.episodes,
                           seed=DEFAULT_EVAL_SEED if args.seed is None else args.seed, tol=tol,
                           attacks=tuple(args.attack))
    what = ("the action cannot change" if result["kind"] == "discrete"
            else f"no action dimension can move more than {tol}")
    print(f"{result['rows'][0]['states']} states of {args.episodes} clean episodes (seeds {result['seed']}..): "
          f"certified = {what} (CROWN or interval bounds: sound, not complete)")
    for row in result["rows"]:
        print(f"  eps {row['eps']:<8g} certified {row['certified_share']:.1%}")
        for side in row.get("attacks", []):
            label = " (white-box)" if side["white_box"] else ""
            print(f"    {side['attack']}{label}: success {side['success_share']:.1%}, unknown "
                  f"{side['unknown_share']:.1%}, {side['queries_per_state']:.0f} queries/state"
                  + (f", {side['contradictions']} CONTRADICTIONS" if side["contradictions"] else ""))
        if len(row.get("attacks", [])) > 1:
            print(f"    any of them: success {row['any_attack']['success_share']:.1%}, "
                  f"unknown {row['any_attack']['unknown_share']:.1%}")
    if args.out is not None:
        write_json(args.out / "certify.json", {**result, "command": command_line()})
        print(f"results: {args.out}/certify.json")
    return 0


def cmd_curves(args: argparse.Namespace) -> int:
    from zodrive.experiments.curves import curves_markdown, plot_curves

    if args.plot:
        _refuse_nonempty(args.plot, args.force, "a figure", "")
    print("mean training return / episode length, per window of training steps (ε-greedy or noisy actions)")
    print(curves_markdown(args.runs, args.bin), end="")
    if args.plot:
        plot_curves(args.runs, args.bin, args.plot)
        print(f"plot: {args.plot}")
    return 0


def cmd_card(args: argparse.Namespace) -> int:
    from zodrive.experiments.card import write_card

    if not args.folder.is_dir():
        raise ZodriveError(f"{args.folder} is not a model folder")
    _refuse_nonempty(args.folder / "CARD.md", args.force, "a card (hand-written notes would be lost)", "")
    path = write_card(args.folder, baseline=args.baseline, evaluation=args.eval, notes=args.note, seeds=args.seeds,
                      attacked=args.attacked)
    print(f"wrote {path}")
    return 0


COMMANDS = {"env": cmd_env, "baselines": cmd_baselines, "train": cmd_train, "evaluate": cmd_evaluate, "render": cmd_render, "card": cmd_card,
            "adv-train": cmd_adv_train, "attack-train": cmd_attack_train, "picker-train": cmd_picker_train, "select": cmd_select, "export": cmd_export, "robust-train": cmd_robust_train, "reproduce": cmd_reproduce,
            "demo": cmd_demo, "compare": cmd_compare, "curves": cmd_curves, "certify": cmd_certify}


def _check_model_paths(args: argparse.Namespace) -> None:
    """A missing model file is reported at once, before torch and highway-env are imported."""
    named = getattr(args, "models", None) if args.command == "compare" else [getattr(args, "model", None)]
    for model in named or []:
        if model is None or str(model).startswith("baseline:"):
            continue
        from zodrive.policies.factory import is_factory, split_factory

        if is_factory(str(model)):
            split_factory(str(model))  # the file must exist
        elif not Path(model).exists():
            raise ZodriveError(f"model file not found: {model}")


def main(argv: Sequence[str] | None = None) -> int:
    from zodrive.runinfo import set_command

    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    argv = list(sys.argv[1:] if argv is None else argv)
    set_command(argv)
    try:
        args = build_parser().parse_args(argv)
        if args.verbose:
            logging.getLogger("zodrive").setLevel(logging.INFO)
        if args.models_dir is not None:
            if not args.models_dir.is_dir():
                raise ZodriveError(f"--models {args.models_dir}: not a folder")
            os.environ[MODELS_ENV] = str(args.models_dir)
        _check_out(getattr(args, "out", None), is_file=args.command == "export")
        _check_plot(getattr(args, "plot", None))
        env_models = os.environ.get(MODELS_ENV)
        if env_models and not Path(env_models).is_dir():
            raise ZodriveError(f"${MODELS_ENV}={env_models}: not a folder")
        _check_model_paths(args)
        return COMMANDS[args.command](args)
    except ZodriveError as exc:
        print(f"zodrive: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        command = argv[0] if argv else ""
        hint = {"train": "run the same command with --resume to continue from the newest checkpoint",
                "adv-train": "the run folder is incomplete: rerun with --force",
                "attack-train": "the adversary folder is incomplete: rerun with --force",
                "picker-train": "a picker is written at the end: rerun (with --force if --out holds files)",
                "robust-train": "the run folder is incomplete: rerun with --force"}.get(
            command, "run the same command again to resume")
        print(f"zodrive: interrupted; results written so far are kept ({hint})", file=sys.stderr)
        return 130
    except OSError as exc:  # a path the checks above could not foresee (a full disk, a vanished folder)
        print(f"zodrive: error: {exc.strerror or exc}: {exc.filename or ''}".rstrip(": "), file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
