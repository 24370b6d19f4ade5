"""The `zodrive` command line. Every user-facing failure is one line on stderr, exit 2.

One module per command group: `evaluate` (evaluate, render, demo, certify), `train` (train,
adv-train, robust-train, attack-train, picker-train, surrogate-train, select, export), `experiments` (reproduce,
compare, curves, card, pack), `info` (env, baselines); `attack` generates the attack flags from the
attack schema, `common` holds what the commands share. Each group adds its parsers
(`add_parsers`) and names its commands (`COMMANDS`); `main` parses, checks what can be checked
before any work, and runs the command.

`zodrive --help` loads no torch and no highway-env: the commands import them inside their
functions.
"""

from __future__ import annotations

import argparse
import io
import logging
import os
import signal
import sys
import threading
from collections.abc import Sequence
from pathlib import Path

from zodrive.cli import bench, evaluate, experiments, info, train
from zodrive.cli.attack import ATTACK_FLAGS, attack_spec_from_args
from zodrive.cli.common import Parser, check_model_paths, check_out, check_plot
from zodrive.config import MODELS_ENV
from zodrive.errors import ZodriveError
from zodrive.runinfo import set_command

__all__ = ["ATTACK_FLAGS", "COMMANDS", "attack_spec_from_args", "build_parser", "main"]

GROUPS = (evaluate, train, experiments, bench, info)
COMMANDS = {name: command for group in GROUPS for name, command in group.COMMANDS.items()}

INTERRUPTED = {
    "train": "run the same command with --resume to continue from the newest checkpoint",
    "adv-train": "the run folder is incomplete: rerun with --force",
    "attack-train": "the adversary folder is incomplete: rerun with --force",
    "picker-train": "a picker is written at the end: rerun (with --force if --out holds files)",
    "surrogate-train": "a surrogate is written at the end: rerun (with --force if --out holds files)",
    "robust-train": "the run folder is incomplete: rerun with --force",
}
"""What a command interrupted by Ctrl-C leaves, and how to go on (default: run it again to resume)."""


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="zodrive", description="Black-box attacks on deep-RL driving policies.")
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    parser.add_argument("--models", dest="models_dir", type=Path, default=None, metavar="DIR",
                        help="folder of shipped models and their SHA256SUMS (default: $ZODRIVE_MODELS or ./models)")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser, metavar="COMMAND")
    for group in GROUPS:
        group.add_parsers(sub)
    return parser


def _terminated(signum: int, frame: object) -> None:
    """SIGTERM (a scheduler, `kill`) ends a run as Ctrl-C does: what was written is kept and said."""
    raise KeyboardInterrupt


def _silence_stdout() -> None:
    """Point stdout at /dev/null, so that flushing what is left at exit does not fail a second time."""
    try:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    except (OSError, ValueError, io.UnsupportedOperation):  # not a real file (a test's capture)
        pass


def main(argv: Sequence[str] | None = None) -> int:
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _terminated)
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
        check_out(getattr(args, "out", None), is_file=args.command in ("export", "leaderboard"))
        check_plot(getattr(args, "plot", None))
        env_models = os.environ.get(MODELS_ENV)
        if env_models and not Path(env_models).is_dir():
            raise ZodriveError(f"${MODELS_ENV}={env_models}: not a folder")
        check_model_paths(args)
        if getattr(args, "address", None) and getattr(args, "backend", "local") != "ray":
            raise ZodriveError("--address joins a Ray cluster: it needs --backend ray")
        code = COMMANDS[args.command](args)
        sys.stdout.flush()  # a reader that went away (`| head`) is met here, not at interpreter exit
        return code
    except BrokenPipeError:  # the reader closed the pipe: stop quietly, as a command in a pipeline should
        _silence_stdout()
        return 141  # 128 + SIGPIPE, what a shell reports for a command its reader cut off
    except ZodriveError as exc:
        print(f"zodrive: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        hint = INTERRUPTED.get(argv[0] if argv else "", "run the same command again to resume")
        print(f"zodrive: interrupted; results written so far are kept ({hint})", file=sys.stderr)
        return 130
    except OSError as exc:  # a path the checks above could not foresee (a full disk, a vanished folder)
        print(f"zodrive: error: {exc.strerror or exc}: {exc.filename or ''}".rstrip(": "), file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
