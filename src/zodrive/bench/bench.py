"""`zodrive bench`: one versioned protocol per scenario, one row per policy, one leaderboard.

A protocol fixes what a row means: the scenario, the evaluation seeds and episodes (clean, and
attacked: the first of the clean seeds, since attacks cost hundreds of queries a step), the ε grid
(normalized units, also stated in metres and m/s), the black-box attack ensemble (every attack
runs at every ε; the row keeps, per ε, the cell that hurts the policy most among all those inside
the ε-ball, smaller ε and clean included) and white-box PGD as a
separate, labelled column where the policy has gradients. Every cell is an ordinary resumable
evaluation (`compare`), so a bench resumes where it stopped; the row is rebuilt from the cells.
A row's folder holds `row.json`, its grid's cells (`cells/`, packed into `cells.jsonl.gz` once finished), `clean/`
(the clean cell of more episodes, its own cells) where the protocol has one, `exact.json` where the row's exact
check ran, and while it is live each grid's `table.json` (one row per cell, `experiments.compare.table_row`); a
packed row's tables are made from its cells (`read_table`), and `zodrive pack` removes each file once they give it
to the bit (`pack_table`). The scenario's brake (`SCENARIO/brake`, `brake_folder`) is a grid of one clean cell,
kept alike. A track (`zodrive.bench.tracks`: decision access, one object, 10 % of steps) is a protocol of its
own on the same grid with another threat model; its rows live in SCENARIO/tracks/TRACK and get tables of
their own. The bench asks the grid for its cells' folders through their `experiments.cells.GridCell` (never a
folder name or a label of its own making); the leaderboard reads the rows (`zodrive.bench.leaderboard`).
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from zodrive.bench.row import read_row, row_key
from zodrive.bench.tracks import (DENSE, TRACK_SCENARIOS, TRACKS, TRACKS_FOLDER, is_dense, share_clean,
                                  threat_fields)
from zodrive.drivers.baselines import PREFIX, get_baseline, is_baseline
from zodrive.envs import load_preset, scenario
from zodrive.errors import ZodriveError
from zodrive.evaluation import store
from zodrive.evaluation.stats import paired_difference_ci
from zodrive.experiments.cells import CLEAN, GridCell, clean_cells, number_name
from zodrive.experiments.compare import TABLE_NEEDS, compare, is_white_box, strongest, table_row
from zodrive.policies.policy import resolve
from zodrive.runinfo import to_json, write_json
from zodrive.seeds import EVAL_SEED

VERSION = 3
"""Version 4 (2026-11-28, highway-fast so far): a black-box attack spends at most `QUERY_CAP` queries a step.
Version 3 (2026-11-27): the clean figures of the four zoo scenarios come from 300 episodes, the
attacked ones still from the first 100 (docs/bench.md, "Citing a version"); the paper's preset keeps
version 2. Version 2: a row's return at ε is the worst over the ε-ball (attacks at every ε' ≤ ε, and
clean); version 1 kept the worst attack at ε alone. Seeds, ε and attacks are unchanged throughout."""
QUERY_CAP = 500
"""Version 4's cap on a black-box attack's queries per step (highway-fast): on tuning seeds it keeps 98 % or
more of the steps each attack of the ensemble wins (`studies/query-cap`), and it bounds a row of a policy
no attack moves (random search's own bound is 2,002 a step)."""
BLACK_BOX = ("random-search", "zo-signsgd")
"""The ensemble: Square-style random search (the strongest per-step black-box attack on most of the
committed cells) and ZO-SignSGD (the paper's attack); each at its shipped settings."""
WHITE_BOX = "pgd"
BRAKE = PREFIX + "slower"
ADAPTIVE = {"kinematic": ("random-search-smooth",), "temporal": ("random-search-smooth",)}
"""The attacks a defended row adds to the ensemble, by defense: a defense is judged by the strongest attack
that knows it. The kinematic filter clamps each row to its one-step prediction, and the temporal median removes
what changes from step to step, so the attacker that knows either holds its perturbation and lets it drift
slowly (`random-search-smooth`: warm start, each step's change limited, `max_change`). The shield and
randomized smoothing are stateless, and smoothing's noise is a function of the observation: the ensemble
queries the system as it is, and each answer is already the vote over the noise (docs/bench.md)."""


@dataclass(frozen=True)
class Protocol:
    """What a bench row of one scenario measures (fixed per version)."""

    scenario: str
    episodes: int
    eps: tuple[float, ...]
    clean_episodes: int = 0
    """Clean episodes (0: `episodes`), on seeds that begin with the attacked ones: the margin over
    the constant actions, the row's first claim, needs more than the attacks can afford."""
    seed: int = EVAL_SEED
    version: int = VERSION
    black_box: tuple[str, ...] = BLACK_BOX
    white_box: str | None = WHITE_BOX
    """The white-box column's attack (None: the row has none, as on the decision track)."""
    query_budget: int | None = None
    """The most victim queries a black-box attack of the row may spend on one step (None: its own
    settings' bound, 2,002 for random search); PGD, white-box, is not capped."""
    track: str = DENSE
    """The threat model's track (`zodrive.bench.tracks`): its protocol has an id and versions of its own."""
    attack_set: tuple[str, ...] = ()
    """The threat-model fields every attack of the row runs with (`KEY=VALUE`; the track's)."""

    def name(self) -> str:
        return f"{self.scenario}{'' if is_dense(self.track) else '-' + self.track}-v{self.version}"

    def counts(self, episodes: int | None = None) -> tuple[int, int]:
        """(attacked, clean) episodes: the protocol's, or `episodes` for both (a quick, unofficial look)."""
        if episodes is not None:
            return episodes, episodes
        return self.episodes, max(self.clean_episodes, self.episodes)


PROTOCOLS = {
    "highway-fast": Protocol("highway-fast", 100, (0.01, 0.02, 0.05), clean_episodes=300, version=4,
                             query_budget=QUERY_CAP),
    "merge": Protocol("merge", 100, (0.01, 0.02, 0.05), clean_episodes=300),
    "roundabout": Protocol("roundabout", 100, (0.01, 0.02, 0.05), clean_episodes=300),
    "intersection": Protocol("intersection", 100, (0.01, 0.02, 0.05), clean_episodes=300),
    "discrete": Protocol("discrete", 30, (0.02, 0.05, 0.2), version=2),  # 450-step episodes, margins in the hundreds
}


TRACK_GRID: dict[str, Any] = {"episodes": 100, "eps": (0.01, 0.02, 0.05), "clean_episodes": 300,
                               "query_budget": QUERY_CAP}
"""Every track's seeds, episodes and ε: its scenario's dense protocol's (highway-fast-v4 and merge-v3 alike; a test
holds them equal, so that a change there is a decision here), and version 4's cap on its black-box attacks on
both scenarios (docs/bench.md, "Tracks")."""
TRACK_PROTOCOLS = {(scenario, name): Protocol(scenario, **TRACK_GRID, version=1, track=name,
                                              black_box=track.black_box or BLACK_BOX,
                                              white_box=WHITE_BOX if track.white_box else None,
                                              attack_set=track.attack_set)
                   for scenario in TRACK_SCENARIOS for name, track in TRACKS.items()}
"""The current protocol of each track on each scenario that has it (`highway-fast-one-object-v1`)."""


def protocol(name: str, track: str = DENSE) -> Protocol:
    """The current protocol of scenario `name` on `track` (the dense one by default)."""
    if name not in PROTOCOLS:
        raise ZodriveError(f"no bench protocol for scenario {name!r} (protocols: {', '.join(PROTOCOLS)})")
    if is_dense(track):
        return PROTOCOLS[name]
    if track not in TRACKS:
        raise ZodriveError(f"no bench track {track!r} (tracks: {', '.join((DENSE, *TRACKS))})")
    if (name, track) not in TRACK_PROTOCOLS:
        raise ZodriveError(f"scenario {name} has no {track} track (its tracks are benched on "
                           f"{' and '.join(TRACK_SCENARIOS)}): bench it on the dense track, without --track")
    return TRACK_PROTOCOLS[(name, track)]


def current_protocols() -> dict[str, Protocol]:
    """Every current protocol, dense and tracks, by id."""
    return {p.name(): p for p in (*PROTOCOLS.values(), *TRACK_PROTOCOLS.values())}


TABLE = "table.json"
"""A grid's table of its finished cells (`compare.write_tables`), kept while the row is live; a packed row's is
made from its cells (`read_table`, `pack_table`)."""
CLEAN_FOLDER, BRAKE_FOLDER = "clean", "brake"
"""A row's grid of more clean episodes (`clean_folder`) and the brake's grid (`brake_folder`): one clean cell each."""

def row_folder(board: Path, scenario: str, name: str, track: str = DENSE) -> Path:
    """Where a bench row lives: BOARD/SCENARIO/NAME on the dense track, BOARD/SCENARIO/tracks/TRACK/NAME on another."""
    return board / scenario / name if is_dense(track) else board / scenario / TRACKS_FOLDER / track / name


def scenario_folder(out: Path, track: str = DENSE) -> Path:
    """The scenario's folder of row folder `out` (`row_folder` backwards): where the board's brake is."""
    return out.parent if is_dense(track) else out.parents[2]


def physical_eps(proto: Protocol) -> dict[str, dict[str, float]]:
    """Each ε of the grid in the scenario's units: how far a normalized ε moves x, y (m) and vx, vy (m/s)."""
    ranges = scenario(load_preset(proto.scenario)).feature_ranges
    return {number_name(eps): {f: round(eps * (hi - lo) / 2, 3) for f, (lo, hi) in sorted(ranges.items())}
            for eps in proto.eps}


class _Clock:
    """What is left of a bench, said on stderr after each cell of its grid: the attacked cells left at the
    pace of those done, then at the clean cell's pace the policy's clean episodes beyond the grid's (its first
    ones are the grid's own) and the board's brake, unless the brake has run already."""

    def __init__(self, episodes: int, clean_episodes: int, brake_done: bool = False) -> None:
        self.start = self.last = time.perf_counter()
        self.episodes, self.clean_episodes, self.brake_done = episodes, clean_episodes, brake_done
        self.clean_s: float | None = None
        self.attacked: list[float] = []

    def cell(self, done: int, total: int, cell: GridCell) -> None:
        now = time.perf_counter()
        took, self.last = now - self.last, now
        if cell.clean:
            self.clean_s = took
        else:
            self.attacked.append(took)
        if not self.attacked or self.clean_s is None:
            return  # nothing to go by yet: a resumed cell takes no time, the first attacked one says the pace
        left = (total - done) * float(np.mean(self.attacked))
        extra = max(self.clean_episodes - self.episodes, 0) + (0 if self.brake_done else self.clean_episodes)
        left += self.clean_s * extra / self.episodes
        print(f"bench: {done}/{total} cells of the grid in {_minutes(now - self.start)}; about {_minutes(left)} "
              "left", file=sys.stderr, flush=True)


def _minutes(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 90 else f"{seconds / 60:.0f} min"


def black_box_of(proto: Protocol, defense: str | None) -> tuple[str, ...]:
    """The black-box ensemble of a row: the protocol's, and for a defended row the attacks that adapt to its
    defense (`ADAPTIVE`)."""
    return proto.black_box + (ADAPTIVE.get(defense.partition("@")[0], ()) if defense else ())


def bench(policy: str, proto: Protocol, out: Path, *, name: str | None = None, episodes: int | None = None,
          workers: int = 1, progress: bool = True, force: bool = False, envs: int = 8,
          trust: bool = False, defense: str | None = None) -> dict[str, Any]:
    """Run the protocol's cells for `policy` (and the constant brake, the row every table is read
    against) into `out`, and write its row (`row.json`). The clean cell of more episodes than the
    attacked ones goes to `out/clean`, beside the attacked grid's own clean cell (the same first
    episodes). `episodes` overrides both counts for a quick look: such a row is marked unofficial.
    `trust` reads an SB3 zip with SB3's own loader (a network zodrive cannot rebuild safely); the row
    says so, for whoever reruns it."""
    n, n_clean = proto.counts(episodes)
    resolved = resolve(policy)
    if defense is not None and resolved.kind == "baseline" and get_baseline(resolved.ref).reads != "observation":
        raise ZodriveError(f"{resolved.ref} does not read the observation: a defense between its sensor and it "
                           "changes nothing (bench it without --defense)")
    if defense is not None and not is_dense(proto.track):
        raise ZodriveError(f"--defense with --track {proto.track}: a defended row is benched on the dense track, whose "
                           "ensemble adds the attacks that adapt to its defense; no track defines them (they drift "
                           "within max_change, which one object does not fit): drop one of the two")
    attacks = [*black_box_of(proto, defense), *([proto.white_box] if proto.white_box else [])]
    capped: dict[str, list[int | None]] | None = (
        {attack: [proto.query_budget] for attack in black_box_of(proto, defense)} if proto.query_budget else None)
    defenses = [defense]
    if force:  # the row of what ran here before is never read beside the new cells (zodrive leaderboard)
        (out / "row.json").unlink(missing_ok=True)
    earlier = _earlier_version(out, proto)
    brake = brake_folder(out, proto.track)
    if not is_dense(proto.track) and not force:  # the clean cells are the dense row's own evaluation: not run twice
        share_clean(policy, proto.scenario, proto.seed, scenario_folder(out, proto.track) / out.name, out,
                    (n, n_clean), trust)
    clock = _Clock(n, n_clean, brake_done=(brake / TABLE).is_file() or bool(clean_cells(brake)))
    cells = compare([policy], attacks, list(proto.eps), n, out, workers=workers, progress=progress, seed=proto.seed,
                    preset=proto.scenario, force=force, envs=envs, trust=trust, on_cell=clock.cell, defenses=defenses,
                    attack_budgets=capped, attack_set=list(proto.attack_set) or None, claim=False, readable=False)
    if earlier:  # cells of the earlier version that this one does not keep (git's history has them)
        keep = {GridCell.from_entry(cell).folder(out) for cell in cells}
        for folder in store.names(out / "cells"):
            if folder not in keep:
                store.remove(folder)
    clean_out = clean_folder(out, n, n_clean)
    if clean_out != out:
        _start_from_grid(out, clean_out, cells, force)
        compare([policy], [], [], n_clean, clean_out, workers=workers, progress=progress, seed=proto.seed,
                preset=proto.scenario, force=force, envs=envs, trust=trust, defenses=defenses, claim=False,
                readable=False)
    # the board's brake, run once for every row of the scenario and every track (never forced: its cell's key
    # decides): it reads nothing, so no threat model changes what it does
    compare([BRAKE], [], [], n_clean, brake, workers=workers, progress=progress, seed=proto.seed,
            preset=proto.scenario, envs=envs, claim=False, readable=False)
    row = bench_row(name or resolved.label, row_key(resolved.key(), defense), proto, out, n, n_clean, defense=defense)
    if trust:
        row["trust_model"] = True
    write_json(out / "row.json", row)
    return row


def brake_folder(out: Path, track: str = DENSE) -> Path:
    """The constant brake's comparison a bench row in `out` (of `track`) is read against: the board's, one per
    scenario and for every track (`BOARD/SCENARIO/brake`), or the row's own `brake/` where it has one (rows
    benched before the brake was shared: the same seeds, the same episodes)."""
    own = out / BRAKE_FOLDER
    return own if own.is_dir() else scenario_folder(out, track) / BRAKE_FOLDER


def _start_from_grid(out: Path, clean_out: Path, cells: list[dict[str, Any]], force: bool) -> None:
    """Seed the clean cell of more episodes with the attacked grid's clean cell: the same evaluation (same key,
    same first seeds), so its first episodes are not run twice; the evaluation resumes from them."""
    (cell,) = [c for c in map(GridCell.from_entry, cells) if c.clean]  # one cell, in both grids
    grid_cell, target = cell.folder(out), cell.folder(clean_out)
    if force or store.exists(target) or not store.exists(grid_cell) or store.read(grid_cell).key is None:
        return
    store.copy_for_resume(grid_cell, target)  # the summary is the finished run's own


def _earlier_version(out: Path, proto: Protocol) -> bool:
    """Whether `out` holds a row of an earlier version of `proto`: then its grid gives way to this version's
    (the cells both share, clean and PGD, are kept and reused; the others are removed once this one has run)."""
    try:
        row = json.loads((out / "row.json").read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError, UnicodeDecodeError):
        return False
    if not isinstance(row, dict) or row.get("scenario") != proto.scenario or row.get("protocol") == proto.name():
        return False
    return True


def _clean(cells: list[dict[str, Any]]) -> dict[str, Any]:
    """The clean cell's entry of a comparison's table (the first, in a grid of several policies)."""
    return next(c for c in cells if GridCell.from_entry(c).clean)


def read_table(out: Path) -> list[dict[str, Any]]:
    """The finished comparison in `out`: its `table.json` where it has one (a grid writes it as each cell
    finishes: a live row), else the rows its cells give (`cells_table`: a packed row, whose file `zodrive pack`
    removed once they were the same, `pack_table`). A damaged or missing record is one line."""
    path = out / TABLE
    if path.is_file():
        try:
            return json.loads(path.read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError):
            raise ZodriveError(f"{path} is damaged (not JSON): run the bench again with --force") from None
    if not store.names(out / "cells"):
        raise ZodriveError(f"{out} holds no finished comparison (table.json, or its cells): run the bench again to "
                           "resume it")
    return cells_table(out)


def cells_table(out: Path) -> list[dict[str, Any]]:
    """The rows of `table.json` of the finished bench grid in `out` (a row's, its `clean/`, a brake's), made
    from its cells as the grid made them (`compare.table_row`), in the grid's order (`bench_row` keeps the first
    of two equal cells): a row's grid is the cells its `row.json` was read from (`_row_cells`), a clean or brake
    grid its one clean cell. A cell missing or one more, or a cell without its summary, is one line: a grid that
    is not finished never reads as one."""
    cleans = clean_cells(out)
    if len(cleans) != 1:
        raise ZodriveError(f"{out} holds {len(cleans)} clean cells, not the one of a bench grid: run the bench again")
    clean = store.summary(cleans[0], needs=TABLE_NEEDS)
    defense = clean.get("defense")
    policy, reads = _grid_policy(cleans[0].name, clean.get("model"), defense)
    row: dict[str, Any] | None = None
    if (out / "row.json").is_file():
        row = read_row(out / "row.json")
        cells = _row_cells(row, policy, defense, reads)
    elif out.name in (CLEAN_FOLDER, BRAKE_FOLDER):
        cells = [GridCell(policy, defense=defense)]
    else:
        raise ZodriveError(f"{out} is not a bench row's grid (no row.json; not a clean/ or brake/ grid): only its "
                           "table.json says which cells it has")
    stored, wanted = {p.name for p in store.names(out / "cells")}, {c.name for c in cells}
    if stored != wanted:
        missing, more = sorted(wanted - stored), sorted(stored - wanted)
        odd = f"cell {missing[0]} is missing" if missing else f"cell {more[0]} is not one of its row's"
        raise ZodriveError(f"{out} is not a finished bench grid: {odd}; run the bench again to resume it")
    rows = []
    for cell in cells:
        summary = store.summary(cell.folder(out), needs=TABLE_NEEDS)
        if row is not None and summary["episodes"] != row["episodes"]:
            raise ZodriveError(f"{cell.folder(out)} holds {summary['episodes']} episodes, its row "
                               f"{row['episodes']}: run the bench again to resume it")
        rows.append(table_row(cell.entry(reads), summary))
    return rows


def _grid_policy(clean: str, ref: Any, defense: str | None) -> tuple[str, str]:
    """The policy's name in a one-policy grid and what it reads (`Policy.reads`), from its clean cell's folder
    name (`GridCell.name`, ':' as '-') and the policy its summary names (`ref`): a baseline's own label where it
    names that folder (`baseline:slower`), else the folder's (a model folder's name, which has no ':')."""
    if isinstance(ref, str) and is_baseline(ref):
        policy = resolve(ref)
        if GridCell(policy.label, defense=defense).name == clean:
            return policy.label, policy.reads
    name = clean.removesuffix(f"-{CLEAN}").removesuffix("" if defense is None else f"+{defense}")
    if GridCell(name, defense=defense).name != clean:
        raise ZodriveError(f"clean cell {clean} is not a bench grid's: its defense is {defense!r}")
    return name, "observation"


def _row_cells(row: dict[str, Any], policy: str, defense: str | None, reads: str) -> list[GridCell]:
    """The cells of the grid a written row was read from, in the order `bench` asks `compare` for them: the clean
    cell, then where the policy reads the observation each attack of the row's ensemble at each ε of the row (at
    its query budget), then the white-box attack at each ε where the row has that column (a policy with
    gradients); each labelled as `compare` labels it (`is_white_box`). An earlier version's row names no
    ensemble: its protocol's, the same in every version."""
    cells = [GridCell(policy, defense=defense)]
    if reads != "observation":
        return cells
    eps = [float(p["eps"]) for p in row["attacked"]]
    proto = current_protocols().get(row["protocol"])
    ensemble = row.get("black_box") or (proto.black_box if proto is not None else BLACK_BOX)
    cells += [GridCell(policy, attack, e, row.get("query_budget"), defense, is_white_box(attack))
              for attack in ensemble for e in eps]
    if any(p.get("pgd_return") is not None for p in row["attacked"]):
        white = row.get("white_box") or WHITE_BOX
        cells += [GridCell(policy, white, e, None, defense, is_white_box(white)) for e in eps]
    return cells


def pack_table(out: Path) -> str:
    """Remove the `table.json` of the bench grid in `out` (a row's, its `clean/`, a brake's) where every cell is
    packed and its cells give the file's rows exactly (`cells_table`: the same JSON, each number to the bit); the
    table is then read from them (`read_table`). Otherwise the file is kept: returns why ('' once removed)."""
    path = out / TABLE
    if any(store.is_live(p) for p in store.names(out / "cells")):
        return "its grid has cells not packed (a live row keeps its table)"
    try:
        written = json.loads(path.read_text(encoding="utf-8"))
        rebuilt = cells_table(out)
    except (json.JSONDecodeError, UnicodeDecodeError):
        return "not JSON"
    except ZodriveError as err:
        return str(err)
    if to_json(rebuilt) != to_json(written):
        return f"its cells do not give its rows exactly ({_first_difference(written, rebuilt)}); the file is kept"
    path.unlink()
    return ""


def pack_tables(root: Path) -> dict[Path, str]:
    """`pack_table` in every folder under `root` (`root` included) that holds a `table.json` beside packed cells;
    each file and why it was kept ('' if removed)."""
    tables = sorted(Path(root).rglob(TABLE))  # `root`'s own file too
    return {path: pack_table(path.parent) for path in tables if store.pack_path(path.parent / "cells").is_file()}


def _first_difference(written: Any, rebuilt: list[dict[str, Any]]) -> str:
    """Where a table file first differs from the rows its cells give, in words."""
    if not isinstance(written, list) or len(written) != len(rebuilt):
        return f"{len(rebuilt)} cells, {len(written) if isinstance(written, list) else 'no list of'} rows in the file"
    for i, (mine, theirs) in enumerate(zip(rebuilt, written), start=1):
        if to_json(mine) != to_json(theirs):
            if not isinstance(theirs, dict):
                return f"row {i} of the file is not a JSON object"
            keys = [k for k in (*mine, *theirs) if to_json(mine.get(k)) != to_json(theirs.get(k))]
            return f"row {i}, {keys[0] if keys else 'the order of its fields'}"
    return "the same rows"


def bench_row(label: str, key: str, proto: Protocol, out: Path, episodes: int,
              clean_episodes: int | None = None, defense: str | None = None) -> dict[str, Any]:
    """The row of a finished bench folder: clean figures, the strongest black-box attack in each ε-ball, PGD
    apart, the robustness area, the ε where collisions pass the brake's, queries to a crash.

    The return at ε is the worst over every cell the ε-ball holds: each black-box attack at every
    ε' ≤ ε, and no perturbation at all (version 2). An attack that finds a point within ε' is an
    attack within ε, so a return that rose with ε (a weaker search in a bigger ball, seen on 15 of 54
    version-1 rows) only measured the search; the envelope is never above a smaller ε's, nor clean.

    With more clean episodes than attacked ones (version 3), the clean figures and the margins come
    from `out/clean`; the envelope, the area and the ε past brake compare the attacks with the clean
    cell of the same episodes (`clean_on_attacked_episodes`)."""
    n_clean = episodes if clean_episodes is None else clean_episodes
    cells = read_table(out)
    same = _clean(cells)  # clean, on the attacked episodes
    clean = _clean(read_table(clean_folder(out, episodes, n_clean)))
    brakes = brake_folder(out, proto.track)
    brake = _clean(read_table(brakes))
    black_box = [c for c in cells if GridCell.from_entry(c).attack in black_box_of(proto, defense)]
    white_box = [c for c in cells if GridCell.from_entry(c).attack == proto.white_box]
    if black_box:
        inside = _inside(black_box, same, proto.eps)
        pgd_inside = _inside(white_box, same, proto.eps) if white_box else {}
        per_eps = [_attacked(out, eps, inside[eps], pgd_inside.get(eps)) for eps in proto.eps]
    else:  # a policy no observation attack reaches (a constant or simulator-reading driver)
        per_eps = [{"eps": eps, "return": same["mean_return"], "collision_rate": same["collision_rate"],
                    "attack": None, "queries_to_crash": None, "pgd_return": None, "pgd_collision_rate": None}
                   for eps in proto.eps]
    returns = [same["mean_return"], *(p["return"] for p in per_eps)]
    grid = [0.0, *proto.eps]
    area = float(np.trapezoid(returns, grid) / (grid[-1] * same["mean_return"])) if same["mean_return"] > 0 else None
    # the smallest ε whose ball holds an attack that collides more often than the brake does clean, on the
    # same episodes (the brake's first `episodes`, not its 300 clean ones: another set of seeds)
    brake_rate = _collision_rate(brakes, episodes)
    passes = 0.0 if same["collision_rate"] > brake_rate else \
        min((c["eps"] for c in black_box if c["collision_rate"] > brake_rate), default=None)
    return {
        "protocol": proto.name(), "official": (episodes, n_clean) == proto.counts(), "policy": label, "key": key,
        "scenario": proto.scenario, "episodes": episodes, "seeds": [proto.seed, proto.seed + episodes - 1],
        "clean_episodes": n_clean, "clean_seeds": [proto.seed, proto.seed + n_clean - 1],
        "clean": {"return": clean["mean_return"], "ci95": [clean["ci95_low"], clean["ci95_high"]],
                  "collision_rate": clean["collision_rate"], "speed": clean["mean_speed"],
                  "offroad_rate": clean.get("offroad_rate")},
        "clean_on_attacked_episodes": {"return": same["mean_return"], "collision_rate": same["collision_rate"]},
        "brake": {"return": brake["mean_return"], "collision_rate": brake["collision_rate"]},
        "attacked": per_eps, "robustness_area": area, "eps_collisions_pass_brake": passes,
        "vs_brake": brake_margin(clean_folder(out, episodes, n_clean), brakes),
        "eps_units": physical_eps(proto),
        **({"defense": defense, "black_box": list(black_box_of(proto, defense))} if defense else {}),
        **({"query_budget": proto.query_budget} if proto.query_budget else {}),
        **({} if is_dense(proto.track) else {"track": proto.track, "threat": threat_fields(proto.attack_set),
                                             "black_box": list(proto.black_box), "white_box": proto.white_box}),
    }


def _attacked(out: Path, eps: float, worst: dict[str, Any], pgd: dict[str, Any] | None) -> dict[str, Any]:
    """A row's entry at ε from the strongest cell inside the ε-ball (clean where no attack hurt more)."""
    attack = {"attack": worst["attack"], "attack_eps": worst["eps"], "queries_per_step": worst["queries_per_step"],
              "queries_to_crash": _median_queries_to_crash(out, worst)} if worst["eps"] is not None else \
        {"attack": None, "attack_eps": 0.0, "queries_per_step": None, "queries_to_crash": None}
    return {"eps": eps, "return": worst["mean_return"], "ci95": [worst["ci95_low"], worst["ci95_high"]],
            "collision_rate": worst["collision_rate"], **attack,
            "pgd_return": pgd["mean_return"] if pgd else None,
            "pgd_collision_rate": pgd["collision_rate"] if pgd else None}


def _inside(attacked: list[dict[str, Any]], clean: dict[str, Any],
            grid: tuple[float, ...]) -> dict[float, dict[str, Any]]:
    """ε of `grid` -> the cell with the lowest mean return inside the ε-ball, from `attacked` and
    clean (compare's `strongest`, for the one policy of a bench folder)."""
    (curve,) = strongest([clean, *attacked]).values()
    return {eps: curve[max(e for e in curve if e <= eps)] for eps in grid}


def brake_margin(clean: Path, brake: Path) -> list[float] | None:
    """The clean return of the comparison folder `clean` minus the constant brake's (folder `brake`),
    paired on the protocol's seeds (episode by episode), with its bootstrap 95% CI: [mean, low, high].
    A policy beats the brake by a margin its CI shows when low > 0. None where a cell's episodes are
    missing or not on the same seeds."""
    return paired(clean_returns(clean), clean_returns(brake))


def clean_folder(out: Path, episodes: int, clean_episodes: int) -> Path:
    """The comparison folder of bench folder `out` that holds the clean cell: `clean/` where there are
    more clean episodes than attacked ones (version 3), else `out` itself."""
    return out / CLEAN_FOLDER if clean_episodes > episodes else out


def row_clean_folder(row: dict[str, Any], out: Path) -> Path:
    """`clean_folder` of a written row (rows before version 3 have no `clean_episodes`)."""
    return clean_folder(out, row["episodes"], row.get("clean_episodes", row["episodes"]))


def clean_returns(folder: Path) -> dict[int, float] | None:
    """Episode -> return of the clean cell of a comparison folder (None: no single clean cell)."""
    cells = clean_cells(folder)
    if len(cells) != 1:
        return None
    return {r["episode"]: r["return"] for r in store.episodes(cells[0], needs=("episode", "return"), missing_ok=True)}


def _collision_rate(folder: Path, episodes: int) -> float:
    """The collision rate of the clean cell of comparison `folder` over its first `episodes` episodes."""
    (cell,) = clean_cells(folder)
    records = [r for r in store.episodes(cell, needs=("episode",), missing_ok=True) if r["episode"] < episodes]
    if len(records) != episodes:
        raise ZodriveError(f"{cell} holds {len(records)} of the first {episodes} episodes: run the bench again")
    return sum(bool(r.get("crashed")) for r in records) / episodes


def paired(mine: dict[int, float] | None, theirs: dict[int, float] | None) -> list[float] | None:
    """[mean, low, high] of mine minus theirs, episode by episode (None unless both hold the same episodes)."""
    if not mine or not theirs or set(mine) != set(theirs):
        return None
    seeds = sorted(mine)
    return list(paired_difference_ci([mine[k] for k in seeds], [theirs[k] for k in seeds]))


def _median_queries_to_crash(out: Path, cell: dict[str, Any]) -> float | None:
    """Median over the attacked episodes that crashed of the queries spent until the crash (an
    episode ends at its crash, so that is the episode's count)."""
    records = store.episodes(GridCell.from_entry(cell).folder(out), needs=("episode",), missing_ok=True)
    crashed = [r["queries"] for r in records if r.get("crashed")]
    return float(np.median(crashed)) if crashed else None
