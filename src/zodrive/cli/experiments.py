"""Grids, tables and reports: `reproduce`, `compare`, `curves`, `card`, `pack`.

The commands import the experiments (torch, highway-env) inside their functions: `zodrive --help`
builds these parsers without loading them.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from zodrive.cli.attack import option_type
from zodrive.cli.common import (
    episode_count,
    backend_flags, defense_or_none, envs_flag, envs_of, nonnegative_int, positive_int, progress_flag,
    refuse_nonempty, scenario_flags, workers_flag,
)
from zodrive.defense import DEFENSE_NAMES
from zodrive.errors import ZodriveError


def add_parsers(sub: Any) -> None:
    rep = sub.add_parser("reproduce", help="the paper's Table 1, figures and a report, in one command")
    rep.add_argument("--out", type=Path, required=True, help="folder for the table, figures and report.html")
    rep.add_argument("--episodes", type=episode_count, help="episodes per cell (default: 100)")
    workers_flag(rep, default=2)
    envs_flag(rep)
    rep.add_argument("--quick", action="store_true",
                     help="5 episodes per cell (a smoke run, minutes); not with --episodes")
    rep.add_argument("--retrain", action="store_true", help="train all four models anew instead of the shipped ones")
    rep.add_argument("--robustness-episodes", type=nonnegative_int, default=10,
                     help="episodes per cell of the robustness section (0: leave it out)")
    progress_flag(rep)
    backend_flags(rep)

    cmp_ = sub.add_parser("compare", help="table of attacks x eps x models (each cell an evaluation)")
    cmp_.add_argument("models", nargs="+", help="SB3 zips, model folders or baseline:NAME")
    cmp_.add_argument("--attacks", nargs="+", default=None,
                      help="default: every registered attack that takes the --attack-set options "
                           "(the others are named)")
    cmp_.add_argument("--eps", nargs="+", type=option_type("eps"), default=[0.2], help="budget radii, one cell each")
    cmp_.add_argument("--query-budgets", nargs="+", type=option_type("query_budget"), default=None,
                      help="per-step query budgets, one cell each (default: no cap)")
    scenario_flags(cmp_, trust=False)  # applied to every model
    cmp_.add_argument("--attack-set", action="append", default=[], metavar="KEY=VALUE",
                      help="attack option for every attack of the grid, e.g. patience=10 (repeatable)")
    cmp_.add_argument("--defense", nargs="+", default=None, type=defense_or_none,
                      metavar="none|" + "|".join(DEFENSE_NAMES),
                      help="defenses in front of each model, one set of cells each (default: none, undefended)")
    cmp_.add_argument("--plot", type=Path, default=None,
                      help="PNG: with --query-budgets, return and success against queries per step; "
                           "otherwise return against eps under the strongest attack inside each eps-ball")
    backend_flags(cmp_)
    cmp_.add_argument("--episodes", type=episode_count, default=20, help="episodes per cell")
    workers_flag(cmp_)
    envs_flag(cmp_)
    cmp_.add_argument("--out", type=Path, required=True, help="folder for the cells and the tables")
    cmp_.add_argument("--force", action="store_true", help="replace the tables of another comparison in --out")
    progress_flag(cmp_)

    curves = sub.add_parser("curves", help="learning curves of training runs side by side (table, --plot PNG)")
    curves.add_argument("runs", nargs="+", type=Path, help="run folders (with monitor.monitor.csv)")
    curves.add_argument("--bin", type=positive_int, default=20000, help="steps per window")
    curves.add_argument("--plot", type=Path, help="also draw the curves to this PNG")
    curves.add_argument("--force", action="store_true", help="overwrite an existing --plot file")

    card = sub.add_parser("card", help="write CARD.md for a trained model folder")
    card.add_argument("folder", type=Path, help="run folder (model.zip, run.json, train.json, eval/)")
    card.add_argument("--baseline", type=Path, help="evaluation folder of the SB3-defaults recipe, for comparison")
    card.add_argument("--eval", type=Path, help="evaluation folder to report (default: FOLDER/eval)")
    card.add_argument("--note", action="append", default=[], help="a line for the card's Notes section (repeatable)")
    card.add_argument("--seeds", nargs="+", type=Path, default=None, metavar="RUN",
                      help="run folders of every training seed (each with eval/): median and range in the card")
    card.add_argument("--attacked", nargs="+", type=Path, default=None, metavar="EVAL",
                      help="evaluation folders of the model under attack, listed in the card")
    card.add_argument("--force", action="store_true",
                      help="replace an existing CARD.md (hand-written sections in it are lost)")

    pack = sub.add_parser("pack", help="pack finished evaluation folders into one file per folder of them "
                                       "(P/NAME/ -> P.jsonl.gz), or give them back (--unpack)")
    pack.add_argument("folders", nargs="+", type=Path, metavar="FOLDER",
                      help="folders to walk: every folder of finished evaluation folders under each (a grid's cells/, "
                           "a bench row's cells/ and clean/cells/, a study's runs) is packed beside itself, and a "
                           "bench grid's table.json removed once its packed cells give it to the bit")
    pack.add_argument("--unpack", action="store_true",
                      help="give every packed evaluation under each FOLDER its folder back, byte for byte")
    pack.add_argument("--logs", action="store_true",
                      help="instead, fold the printed outputs in each FOLDER (its NAME.txt files) into one FOLDER.txt "
                           "beside it, each under a '==> NAME.txt <==' line (with --unpack: give them back)")
    pack.add_argument("--match", action="append", metavar="GLOB",
                      help="with --logs: fold only the logs whose names match GLOB (repeatable; default: every "
                           "NAME.txt), say a study's training printouts and not the tables its scripts print")


def cmd_reproduce(args: argparse.Namespace) -> int:
    from zodrive.experiments.report import table_markdown
    from zodrive.experiments.reproduce import reproduce

    if args.quick and args.episodes is not None:
        raise ZodriveError("--quick runs 5 episodes per cell; --episodes would be ignored: give one of them")
    table = reproduce(args.out, episodes=args.episodes or 100, workers=args.workers, quick=args.quick,
                      robustness_episodes=args.robustness_episodes,
                      retrain=args.retrain, progress=not args.no_progress, backend=args.backend, address=args.address,
                      envs=envs_of(args))
    print(table_markdown(table["rows"]), end="")
    print(f"report: {args.out}/report.html")
    return 0


def cmd_compare(args: argparse.Namespace) -> int:
    from zodrive.experiments.compare import compare, default_attacks, markdown, plot_budget_curves, plot_robustness

    defenses = [None if d == "none" else d for d in args.defense or ["none"]]
    if args.plot and args.out.resolve() not in args.plot.resolve().parents:  # inside --out it is the grid's own
        refuse_nonempty(args.plot, args.force, "a figure", "")
    attacks = args.attacks
    if not attacks:  # every attack that takes the --attack-set options; the others are named
        attacks, left_out = default_attacks(args.attack_set)
        for name, why in left_out.items():
            print(f"({name} left out of the default attacks: {why})", file=sys.stderr)
    rows = compare(args.models, attacks, args.eps, args.episodes, args.out,
                   workers=args.workers, progress=not args.no_progress, query_budgets=args.query_budgets,
                   backend=args.backend, address=args.address, defenses=defenses, env_set=args.env_set,
                   attack_set=args.attack_set, preset=args.preset, env_id=args.env_id, obs_bounds=args.obs_bounds,
                   shifted=args.shifted,
                   force=args.force, envs=envs_of(args))
    print(markdown(rows), end="")
    if args.plot:
        (plot_budget_curves if args.query_budgets else plot_robustness)(rows, args.plot)
        print(f"plot: {args.plot}")
    return 0


def cmd_curves(args: argparse.Namespace) -> int:
    from zodrive.experiments.curves import curves_markdown, plot_curves

    if args.plot:
        refuse_nonempty(args.plot, args.force, "a figure", "")
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
    refuse_nonempty(args.folder / "CARD.md", args.force, "a card (hand-written notes would be lost)", "")
    path = write_card(args.folder, baseline=args.baseline, evaluation=args.eval, notes=args.note, seeds=args.seeds,
                      attacked=args.attacked)
    print(f"wrote {path}")
    return 0


def cmd_pack(args: argparse.Namespace) -> int:
    from zodrive.bench.bench import pack_tables
    from zodrive.evaluation import store

    if args.match and (not args.logs or args.unpack):
        raise ZodriveError("--match chooses the logs that --logs folds: give it with --logs, without --unpack")
    if args.logs:
        return _pack_logs(args.folders, args.unpack, tuple(args.match or ("*.txt",)))
    for folder in args.folders:
        if not folder.is_dir():
            raise ZodriveError(f"{folder}: not a folder")
    for folder in args.folders:
        if args.unpack:
            for pack, names in store.unpack_tree(folder).items():
                print(f"unpacked {pack}: {len(names)} evaluation folder{'s' * (len(names) != 1)}")
            continue
        if store.is_evaluation(folder):
            raise ZodriveError(f"{folder} is an evaluation folder: pack the folder that holds it ({folder.parent})")
        for done in store.pack_tree(folder):
            if done.packed:
                print(f"packed {len(done.packed)} evaluation folder{'s' * (len(done.packed) != 1)} into {done.pack}")
            for name, why in done.left.items():
                print(f"left {done.pack.with_name(done.pack.name[:-len(store.PACKED)]) / name}: {why}")
        for table, why in pack_tables(folder).items():  # a bench grid's table, once its packed cells give it
            print(f"left {table}: {why}" if why else f"removed {table}: its packed cells give it")
    return 0


def _pack_logs(folders: list[Path], unpack: bool, patterns: tuple[str, ...]) -> int:
    """`zodrive pack --logs [--unpack] FOLDER...`: each FOLDER's printed outputs, folded or given back."""
    from zodrive.evaluation import store

    for folder in folders:
        if unpack and not store.logs_path(folder).is_file():
            raise ZodriveError(f"{store.logs_path(folder)}: no such file (no logs of {folder} are folded)")
        if not unpack and not folder.is_dir():
            raise ZodriveError(f"{folder}: not a folder")
    for folder in folders:
        if unpack:
            names = store.unpack_logs(folder)
            print(f"unpacked {store.logs_path(folder)}: {len(names)} log{'s' * (len(names) != 1)} into {folder}")
            continue
        done = store.pack_logs(folder, patterns)
        if done.packed:
            print(f"folded {len(done.packed)} log{'s' * (len(done.packed) != 1)} into {done.pack}")
        for name, why in done.left.items():
            print(f"left {folder / name}: {why}")
    return 0


COMMANDS = {"reproduce": cmd_reproduce, "compare": cmd_compare, "curves": cmd_curves, "card": cmd_card,
            "pack": cmd_pack}
