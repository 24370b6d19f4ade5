"""What the commands share: the parser and its help formatter, argument types, the flags several
commands take, and the checks made before any work (paths we can write, nothing overwritten
without --force).

Light imports only (no torch, no highway-env): `zodrive --help` builds every parser. What a
check needs from a heavier module is imported inside it.
"""

from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path
from typing import Any, Callable, NoReturn

from zodrive.defense import parse_defense
from zodrive.errors import ZodriveError
from zodrive.seeds import MAX_EPISODES


# -- the parser ----------------------------------------------------------------------------
class Help(argparse.HelpFormatter):
    """Shows an option's default as "(default: X)", once: not where the help already states one,
    not for an option without one (None, an empty list), and not for a switch (`--force`,
    `--no-warm-start`), whose default is only "not given"."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        if (action.nargs == 0 or default in (None, argparse.SUPPRESS) or default == [] or "default" in text
                or not action.option_strings):
            return text
        shown = " ".join(map(str, default)) if isinstance(default, (list, tuple)) else str(default)
        return f"{text} (default: {shown.replace('%', '%%')})"


class Parser(argparse.ArgumentParser):
    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", Help)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:  # one line, exit 2, like every other error
        command = self.prog.partition(" ")[2]  # "zodrive evaluate" -> "evaluate"; main adds "zodrive: error:"
        raise ZodriveError(f"{command}: {message}" if command else message)


# -- argument types --------------------------------------------------------------------------
def int_at_least(least: int, what: str, most: int | None = None) -> Callable[[str], int]:
    """An argparse type: an integer >= `least` (and <= `most`), with a one-line message naming `what`."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if value < least or (most is not None and value > most):
            raise argparse.ArgumentTypeError(f"expected {what}" + (f" (at most {most:,})" if most else "")
                                             + f", got {value}")
        return value

    return parse


episode_count = int_at_least(1, "a positive integer", MAX_EPISODES)
"""--episodes: bounded before anything is allocated (a million episodes is days of CPU)."""


def float_above(least: float, strict: bool, what: str) -> Callable[[str], float]:
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


positive_int = int_at_least(1, "a positive integer")
nonnegative_int = int_at_least(0, "an integer >= 0")
seed_number = int_at_least(0, "a seed (an integer >= 0)")
positive_float = float_above(0.0, True, "a finite number > 0")
nonnegative_float = float_above(0.0, False, "a finite number >= 0")


def probability_below_one(text: str) -> float:
    """An argparse type: a number in [0, 1)."""
    value = nonnegative_float(text)
    if value >= 1:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1), got {text}")
    return value


def obs_bounds(text: str) -> tuple[float, float]:
    """An argparse type: `LOW,HIGH` with LOW < HIGH."""
    try:
        low, high = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LOW,HIGH (two numbers), got {text!r}") from None
    if not low < high:
        raise argparse.ArgumentTypeError(f"expected LOW < HIGH, got {text!r}")
    return low, high


def defense_name(text: str) -> str:
    """`--defense`: a known defense, canonical (`shield` -> `shield@0.02`); else a one-line error."""
    try:
        return parse_defense(text)
    except ZodriveError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def defense_or_none(text: str) -> str:
    return "none" if text == "none" else defense_name(text)


# -- flags several commands take ------------------------------------------------------------
MODEL_HELP = ("SB3 / sb3-contrib zip, model folder, ONNX file, FILE.py:NAME (runs that code) or baseline:NAME "
              "(see `zodrive baselines`)")


def scenario_flags(parser: argparse.ArgumentParser, *, trust: bool = True) -> None:
    """Where a policy drives: a preset or any gymnasium id; and how to read an SB3 zip."""
    parser.add_argument("--preset", help="preset (`zodrive env list`; default: where the model's folder says it was "
                                         "trained; a baseline: the paper's preset of its kind)")
    parser.add_argument("--env-id", metavar="ID",
                        help="any gymnasium environment with a Box observation, instead of --preset")
    parser.add_argument("--obs-bounds", type=obs_bounds, metavar="LOW,HIGH",
                        help="with --env-id: the range of a clean observation value, when the env does not "
                             "declare one finite interval (the attack's box)")
    env_set_flag(parser)
    parser.add_argument("--shifted", action="store_true",
                        help="run on --preset / --env-id although the model's files say it was trained on another "
                             "scenario (a distribution-shift measurement; without it that is refused)")
    if trust:
        trust_flag(parser)


def env_set_flag(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env-set", action="append", default=[], metavar="KEY=VALUE",
                        help="preset override, e.g. highway.lanes_count=3 (repeatable)")


def trust_flag(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--trust-model", action="store_true",
                        help="read an SB3 zip with stable-baselines3's own loader, which unpickles it (can run "
                             "code from the file): for models zodrive cannot rebuild safely")


def progress_flag(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--no-progress", action="store_true", help="draw no progress bar")


def workers_flag(parser: argparse.ArgumentParser, default: int = 1) -> None:
    parser.add_argument("--workers", type=positive_int, default=default, help="worker processes")


def envs_flag(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--envs", type=positive_int, default=None,
                        help="episodes each worker runs side by side, attacked in one call per step; the records "
                             "are the same for every value (default: 8; 1 under a frequency budget or for a policy "
                             "that reads its simulator)")


def envs_of(args: argparse.Namespace, *jobs: Any) -> int:
    """`--envs`, or the default; an explicit value above 1 that some job cannot use is an error."""
    from zodrive.evaluation.evaluate import DEFAULT_ENVS, lockstep_blocker

    if args.envs is None:
        return DEFAULT_ENVS
    reasons = [reason for job in jobs if args.envs > 1 and (reason := lockstep_blocker(job))]
    if reasons:
        raise ZodriveError(f"--envs {args.envs}: episodes cannot run side by side here ({reasons[0]}); use --envs 1")
    return args.envs


def backend_flags(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--backend", choices=["local", "ray"], default="local",
                        help="where cells run: this process (episodes over --workers) or Ray tasks (cells in parallel)")
    parser.add_argument("--address", default=None,
                        help="Ray cluster address (default: a local Ray instance with --workers CPUs)")


# -- checks before any work ----------------------------------------------------------------
def writable_folder(path: Path, flag: str) -> None:
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


def check_out(path: Path | None, *, is_file: bool = False) -> None:
    """An --out must be a folder (or a file, for export) that we can create and write to."""
    if path is None:
        return
    if is_file:
        if path.is_dir():
            raise ZodriveError(f"--out {path} is a folder; give the file to write")
        writable_folder(path.parent if str(path.parent) else Path("."), "--out")
        return
    writable_folder(path, "--out")


PLOT_SUFFIXES = (".png", ".pdf", ".svg")


def check_plot(path: Path | None, flag: str = "--plot") -> None:
    """A figure path: an image file (not a folder) in a place we can write, checked before any work."""
    if path is None:
        return
    if path.is_dir() or path.suffix.lower() not in PLOT_SUFFIXES:
        raise ZodriveError(f"{flag} {path}: give an image file ending in {', '.join(PLOT_SUFFIXES)}")
    writable_folder(path.parent if str(path.parent) else Path("."), flag)


def refuse_nonempty(path: Path, force: bool, what: str, elsewhere: str = ", or choose another --out") -> None:
    """Nothing is overwritten without --force."""
    if force:
        return
    if path.is_dir() and any(path.iterdir()) or path.is_file():
        raise ZodriveError(f"{path} already holds {what}; use --force to overwrite it{elsewhere}")


def check_model_paths(args: argparse.Namespace) -> None:
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


def preset_of(args: argparse.Namespace) -> dict[str, Any]:
    """Where `args.model` drives: --preset, --env-id (with --obs-bounds) or where its files say (`scenario_of`)."""
    return scenario_of(args)[0]


def scenario_of(args: argparse.Namespace, policy: Any = None) -> tuple[dict[str, Any], str | None]:
    """`preset_of` and where a scenario the user did not name came from (`resolve_scenario`), for
    `policy` (`args.model`'s `Policy`, where the command has resolved it already) or `args.model`."""
    from zodrive.policies.resolve import refuse_unused_shift, resolve_scenario

    shifted = getattr(args, "shifted", False)
    found = resolve_scenario(args.model if policy is None else policy, args.preset, args.env_set,
                             getattr(args, "env_id", None), getattr(args, "obs_bounds", None), shifted=shifted)
    if shifted:
        refuse_unused_shift([found[1]], "--shifted")
    return found


def check_trust(args: argparse.Namespace, policy: Any = None) -> None:
    """--trust-model reads SB3 zips; for anything else it would be ignored: an error (`policy`: `args.model`'s
    `Policy`, where the command has resolved it already)."""
    if getattr(args, "trust_model", False):
        from zodrive.policies.policy import resolve

        if resolve(args.model if policy is None else policy).kind != "model":
            raise ZodriveError("--trust-model applies to stable-baselines3 zips; this model is read without it")
