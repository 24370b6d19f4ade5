"""The yardstick: `bench` (one policy's row under a scenario's fixed protocol) and `leaderboard`
(the tables and the plot, generated from every row)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from zodrive.bench.tracks import DENSE, RESERVED, TRACKS
from zodrive.cli.common import check_trust, defense_name, episode_count, progress_flag, trust_flag, workers_flag
from zodrive.errors import ZodriveError

BOARD = Path("results/bench")
SCENARIOS = ("highway-fast", "merge", "roundabout", "intersection", "discrete")


def add_parsers(sub: Any) -> None:
    bench = sub.add_parser("bench", help="a policy's row under a scenario's fixed protocol (docs/bench.md)")
    bench.add_argument("model", help="the policy: SB3 zip or folder, ONNX file, FILE.py:NAME or baseline:NAME")
    bench.add_argument("--scenario", required=True, choices=SCENARIOS, help="the protocol's scenario")
    bench.add_argument("--track", choices=(DENSE, *TRACKS), default=DENSE,
                       help="the threat model, a protocol of its own: dense (every feature of every vehicle, every "
                            "step, score access), decision (the attacker sees only the action taken), one-object (at "
                            "most one vehicle row moved a step), sparse (at most 10%% of the steps attacked); "
                            "docs/bench.md, \"Tracks\" (default: dense)")
    bench.add_argument("--name", help="the row's name on the leaderboard (default: the model's label)")
    bench.add_argument("--board", type=Path, default=BOARD,
                       help="leaderboard folder: the row goes to BOARD/SCENARIO/NAME, a track's to "
                            "BOARD/SCENARIO/tracks/TRACK/NAME (default: results/bench)")
    bench.add_argument("--episodes", type=episode_count, default=None,
                       help="N episodes, clean and attacked alike, for a quick look: the row is marked unofficial "
                            "(default: the protocol's)")
    bench.add_argument("--defense", type=defense_name, default=None,
                       help="bench the defended system: the defense stands between the sensor and the policy, every "
                            "attack queries the defended system, and the ensemble adds the attacks that adapt to it "
                            "(docs/bench.md); the row's name and key cover both (default name: MODEL+DEFENSE)")
    bench.add_argument("--force", action="store_true", help="replace another bench in the row's folder")
    trust_flag(bench)
    workers_flag(bench)
    progress_flag(bench)

    board = sub.add_parser("leaderboard", help="the leaderboard's tables and plot, generated from the bench rows")
    board.add_argument("--board", type=Path, default=BOARD, help="folder of bench rows (default: results/bench)")
    board.add_argument("--out", type=Path, required=True,
                       help="the Markdown file to write (the repository's own board: docs/leaderboard.md)")
    board.add_argument("--plot", type=Path, default=None, help="also draw return against eps per scenario (PNG)")
    board.add_argument("--frontier", type=Path, default=None,
                       help="also draw clean return against the return at the largest eps, per table (PNG)")
    board.add_argument("--force", action="store_true",
                       help="replace a --out, --plot or --frontier file zodrive did not write")


def cmd_bench(args: argparse.Namespace) -> int:
    import time

    from zodrive.bench.bench import bench, protocol, row_folder
    from zodrive.bench.leaderboard import write_leaderboard
    from zodrive.bench.row import ROW_NAME
    from zodrive.policies.policy import resolve

    proto = protocol(args.scenario, args.track)
    check_trust(args)
    name = (resolve(args.model).label.replace(":", "-") + (f"+{args.defense}" if args.defense else "")
            if args.name is None else args.name)
    if not ROW_NAME.fullmatch(name):
        raise ZodriveError(f"--name {name!r}: a row's name is one folder name of letters, digits and ._+@=- (at most "
                           "100, not starting with one of ._+@=-): tables and plots show it as it is"
                           + ("" if args.name is not None else "; pass --name"))
    if name in RESERVED:
        raise ZodriveError(f"--name {name}: the board's own folder of a scenario ({', '.join(RESERVED)}), not a row's: "
                           "pass another --name")
    out = row_folder(args.board, args.scenario, name, args.track)
    start = time.perf_counter()
    row = bench(args.model, proto, out, name=name, episodes=args.episodes, workers=args.workers,
                progress=not args.no_progress, force=args.force, trust=args.trust_model, defense=args.defense)
    clean, worst = row["clean"], row["attacked"][-1]
    print(f"{row['policy']} on {row['protocol']}{'' if row['official'] else ' (unofficial: fewer episodes)'}: "
          f"clean {clean['return']:.2f} ({100 * clean['collision_rate']:.0f}% collisions), at eps {worst['eps']:g} "
          f"{worst['return']:.2f} ({100 * worst['collision_rate']:.0f}%), area "
          f"{'n/a' if row['robustness_area'] is None else format(row['robustness_area'], '.2f')} "
          f"[{time.perf_counter() - start:.0f} s]")
    print(f"row: {out / 'row.json'}")
    write_leaderboard(args.board, args.board / "leaderboard.md")
    print(f"leaderboard: {args.board / 'leaderboard.md'}")
    return 0


def cmd_leaderboard(args: argparse.Namespace) -> int:
    from zodrive.bench.leaderboard import write_leaderboard

    write_leaderboard(args.board, args.out, args.plot, frontier=args.frontier, force=args.force)
    print(f"wrote {', '.join(str(p) for p in (args.out, args.plot, args.frontier) if p is not None)}")
    return 0


COMMANDS = {"bench": cmd_bench, "leaderboard": cmd_leaderboard}
