"""`zodrive bench`: one versioned protocol per scenario, one row per policy, one leaderboard.

A protocol fixes what a row means: the scenario, the evaluation seeds and episodes (clean, and
attacked: the first of the clean seeds, since attacks cost hundreds of queries a step), the ε grid
(normalized units, also stated in metres and m/s), the black-box attack ensemble (every attack
runs at every ε; the row keeps, per ε, the cell that hurts the policy most among all those inside
the ε-ball, smaller ε and clean included) and white-box PGD as a
separate, labelled column where the policy has gradients. Every cell is an ordinary resumable
evaluation (`compare`), so a bench resumes where it stopped; the row is rebuilt from the cells.
A track (`zodrive.experiments.tracks`: decision access, one object, 10 % of steps) is a protocol of its
own on the same grid with another threat model; its rows live in SCENARIO/tracks/TRACK and get tables of
their own.
"""

from __future__ import annotations

import json
import re
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from zodrive.defense import defense_version
from zodrive.drivers.baselines import BASELINES, PREFIX, get_baseline
from zodrive.envs import load_preset, scenario
from zodrive.errors import ZodriveError
from zodrive.evaluation import store
from zodrive.evaluation.stats import paired_difference_ci
from zodrive.experiments.cells import GridCell, clean_cells, number_name
from zodrive.experiments.compare import compare, strongest
from zodrive.experiments.exact_board import exact_cells, exact_headers, exact_notes, read_exact
from zodrive.experiments.tracks import (DENSE, TRACK_SCENARIOS, TRACKS, TRACKS_FOLDER, is_dense, share_clean,
                                        threat_fields)
from zodrive.policies.policy import resolve
from zodrive.runinfo import write_atomic, write_json
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
    """The threat model's track (`zodrive.experiments.tracks`): its protocol has an id and versions of its own."""
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
    clock = _Clock(n, n_clean, brake_done=(brake / "table.json").is_file())
    cells = compare([policy], attacks, list(proto.eps), n, out, workers=workers, progress=progress, seed=proto.seed,
                    preset=proto.scenario, force=force, envs=envs, trust=trust, on_cell=clock.cell, defenses=defenses,
                    attack_budgets=capped, attack_set=list(proto.attack_set) or None)
    if earlier:  # cells of the earlier version that this one does not keep (git's history has them)
        keep = {GridCell.from_entry(cell).folder(out) for cell in cells}
        for folder in store.names(out / "cells"):
            if folder not in keep:
                store.remove(folder)
    clean_out = clean_folder(out, n, n_clean)
    if clean_out != out:
        _start_from_grid(out, clean_out, cells, force)
        compare([policy], [], [], n_clean, clean_out, workers=workers, progress=progress, seed=proto.seed,
                preset=proto.scenario, force=force, envs=envs, trust=trust, defenses=defenses)
    # the board's brake, run once for every row of the scenario and every track (never forced: its cell's key
    # decides): it reads nothing, so no threat model changes what it does
    compare([BRAKE], [], [], n_clean, brake, workers=workers, progress=progress, seed=proto.seed,
            preset=proto.scenario, envs=envs)
    key = resolved.key() if defense is None else f"{resolved.key()}+defense:{defense}" + (
        f":v{defense_version(defense)}" if defense_version(defense) is not None else "")
    row = bench_row(name or resolved.label, key, proto, out, n, n_clean, defense=defense)
    if trust:
        row["trust_model"] = True
    write_json(out / "row.json", row)
    return row


def brake_folder(out: Path, track: str = DENSE) -> Path:
    """The constant brake's comparison a bench row in `out` (of `track`) is read against: the board's, one per
    scenario and for every track (`BOARD/SCENARIO/brake`), or the row's own `brake/` where it has one (rows
    benched before the brake was shared: the same seeds, the same episodes)."""
    own = out / "brake"
    return own if own.is_dir() else scenario_folder(out, track) / "brake"


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
    (out / "grid.json").unlink(missing_ok=True)
    return True


def _clean(cells: list[dict[str, Any]]) -> dict[str, Any]:
    """The clean cell's entry of a comparison's table (the first, in a grid of several policies)."""
    return next(c for c in cells if GridCell.from_entry(c).clean)


def _cells(out: Path) -> list[dict[str, Any]]:
    """The finished comparison in `out` (its `table.json`)."""
    path = out / "table.json"
    if not path.is_file():
        raise ZodriveError(f"{out} holds no finished comparison (table.json): run the bench again to resume it")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError):
        raise ZodriveError(f"{path} is damaged (not JSON): run the bench again with --force") from None


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
    cells = _cells(out)
    same = _clean(cells)  # clean, on the attacked episodes
    clean = _clean(_cells(clean_folder(out, episodes, n_clean)))
    brakes = brake_folder(out, proto.track)
    brake = _clean(_cells(brakes))
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
    return _paired(_clean_returns(clean), _clean_returns(brake))


def clean_folder(out: Path, episodes: int, clean_episodes: int) -> Path:
    """The comparison folder of bench folder `out` that holds the clean cell: `clean/` where there are
    more clean episodes than attacked ones (version 3), else `out` itself."""
    return out / "clean" if clean_episodes > episodes else out


def row_clean_folder(row: dict[str, Any], out: Path) -> Path:
    """`clean_folder` of a written row (rows before version 3 have no `clean_episodes`)."""
    return clean_folder(out, row["episodes"], row.get("clean_episodes", row["episodes"]))


def _clean_returns(folder: Path) -> dict[int, float] | None:
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


def _paired(mine: dict[int, float] | None, theirs: dict[int, float] | None) -> list[float] | None:
    """[mean, low, high] of mine minus theirs, episode by episode (None unless both hold the same episodes)."""
    if not mine or not theirs or set(mine) != set(theirs):
        return None
    seeds = sorted(mine)
    return list(paired_difference_ci([mine[k] for k in seeds], [theirs[k] for k in seeds]))


def constant_margins(rows: list[tuple[dict[str, Any], Path]]) -> None:
    """Give each row `vs_constants`: its clean return minus each constant action's (the rows of
    `baseline:NAME` constants of the same protocol on the board), paired on the same seeds. A policy
    beats every constant by a margin its CI shows when every low end is above 0."""
    returns = [_clean_returns(row_clean_folder(row, folder)) for row, folder in rows]  # each row's episodes, read once
    constants: dict[str, dict[str, dict[int, float] | None]] = {}
    for (row, _), theirs in zip(rows, returns):
        name = row["key"].removeprefix(PREFIX) if row["key"].startswith(PREFIX) else None
        if name in BASELINES and BASELINES[name].action is not None:
            constants.setdefault(row["protocol"], {})[name] = theirs
    for (row, _), mine in zip(rows, returns):
        row["vs_constants"] = {name: _paired(mine, theirs)
                               for name, theirs in constants.get(row["protocol"], {}).items()
                               if row["key"] != PREFIX + name}


def _worst_returns(row: dict[str, Any], out: Path) -> dict[int, float] | None:
    """Episode -> return of the cell a row keeps at its largest ε (the worst black-box attack inside the
    ball, or the clean cell of the attacked episodes where no attack hurt more); None if it is not there."""
    last = row["attacked"][-1]
    if last.get("attack") is None:
        return _clean_returns(out)
    try:
        cells = _cells(out)
    except ZodriveError:
        return None
    kept = (c for c in map(GridCell.from_entry, cells) if c.attack == last["attack"] and c.eps == last["attack_eps"])
    cell = next(kept, None)
    if cell is None:
        return None
    records = store.episodes(cell.folder(out), needs=("episode", "return"), missing_ok=True)
    return {r["episode"]: r["return"] for r in records}


def defense_margins(rows: list[tuple[dict[str, Any], Path]]) -> None:
    """Give each defended row `vs_undefended`: the row of the same policy without the defense (same protocol,
    the key before `+defense:`), the clean return's difference (defended minus undefended, over the clean
    episodes) and the difference at the largest ε (the worst attack each row kept, over the attacked
    episodes), each paired on the same seeds with its bootstrap 95% CI. What a defense costs clean and what
    it buys under attack, read on one board."""
    plain = {(row["protocol"], row["key"]): (row, folder) for row, folder in rows if not row.get("defense")}
    for row, folder in rows:
        if not row.get("defense"):
            continue
        match = plain.get((row["protocol"], row["key"].split("+defense:")[0]))
        if match is None:
            continue
        other, other_folder = match
        row["vs_undefended"] = {
            "policy": other["policy"],
            "clean": _paired(_clean_returns(row_clean_folder(row, folder)),
                             _clean_returns(row_clean_folder(other, other_folder))),
            "attacked": _paired(_worst_returns(row, folder), _worst_returns(other, other_folder)),
            "eps": row["attacked"][-1]["eps"]}


def _median_queries_to_crash(out: Path, cell: dict[str, Any]) -> float | None:
    """Median over the attacked episodes that crashed of the queries spent until the crash (an
    episode ends at its crash, so that is the episode's count)."""
    records = store.episodes(GridCell.from_entry(cell).folder(out), needs=("episode",), missing_ok=True)
    crashed = [r["queries"] for r in records if r.get("crashed")]
    return float(np.median(crashed)) if crashed else None


# ---------------------------------------------------------------- the leaderboard

ROW_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._+@=-]{0,99}")
"""A row's name: one folder name that a Markdown table and a plot legend show as it is (no `|`, no newline)."""
MAX_ROW_BYTES = 4 << 20  # a row is a few KiB: a larger file is not one


class _Point(BaseModel):
    model_config = ConfigDict(extra="allow")
    eps: float
    collision_rate: float = Field(ge=0, le=1)
    pgd_return: float | None = None
    queries_to_crash: float | None = None
    return_: float = Field(alias="return")


class _Clean(BaseModel):
    model_config = ConfigDict(extra="allow")
    return_: float = Field(alias="return")
    collision_rate: float = Field(ge=0, le=1)


class _Row(BaseModel):
    """What the leaderboard reads of a row, checked before it reads it (rows come from strangers too)."""

    model_config = ConfigDict(extra="allow")
    protocol: str
    official: bool
    policy: str = Field(pattern=f"^{ROW_NAME.pattern}$")  # anchored: pydantic searches
    scenario: str
    episodes: int = Field(ge=1)
    clean_episodes: int | None = Field(default=None, ge=1)
    clean: _Clean
    clean_on_attacked_episodes: _Clean | None = None
    attacked: list[_Point] = Field(min_length=1)
    robustness_area: float | None
    eps_collisions_pass_brake: float | None
    track: str | None = Field(default=None, pattern=r"^[a-z][a-z0-9-]{0,39}$")  # a table's heading shows it


def read_row(path: Path) -> dict[str, Any]:
    """One `row.json`, read only if it is a regular file of a row's size, and checked for the fields the
    leaderboard reads: anything else is one line naming the file."""
    if not path.is_file() or path.stat().st_size > MAX_ROW_BYTES:
        raise ZodriveError(f"{path} is not a bench row (not a regular file of at most {MAX_ROW_BYTES >> 20} MiB)")
    try:
        row = json.loads(path.read_text(encoding="utf-8"))
        _Row.model_validate(row)
        if len([float(v) for v in row["clean"]["ci95"]]) != 2:  # numbers, or a ValueError / TypeError
            raise ValueError("ci95 is not two numbers")
        float(row["clean"]["speed"])
    except (json.JSONDecodeError, UnicodeDecodeError):
        raise ZodriveError(f"{path} is not a bench row (damaged JSON): run its bench again") from None
    except ValidationError as exc:
        first = exc.errors()[0]
        raise ZodriveError(f"{path} is not a bench row: {'.'.join(map(str, first['loc']))}: {first['msg']}") from None
    except (KeyError, TypeError, ValueError) as exc:
        raise ZodriveError(f"{path} is not a bench row: its clean ci95 and speed must be numbers ({exc})") from None
    return row


def read_rows(board: Path) -> list[dict[str, Any]]:
    """Every `row.json` under `board` (one folder per scenario, one per policy; a track's rows in
    SCENARIO/tracks/TRACK, `row_folder`)."""
    rows = []
    for path in sorted([*board.glob("*/*/row.json"), *board.glob(f"*/{TRACKS_FOLDER}/*/*/row.json")]):
        row = read_row(path)
        if "vs_brake" not in row:  # a row written before the column: from its own cells
            row["vs_brake"] = brake_margin(row_clean_folder(row, path.parent),
                                           brake_folder(path.parent, row.get("track") or DENSE))
        row["exact"] = read_exact(path.parent)
        rows.append((row, path.parent))
    constant_margins(rows)
    defense_margins(rows)
    return [row for row, _ in rows]


def leaderboard_markdown(rows: list[dict[str, Any]]) -> str:
    """One table per scenario, ranked by the return under the strongest attack at the largest ε (as
    RobustBench ranks by robust accuracy), then by clean return; unofficial rows (fewer episodes) in a
    table of their own below it, never ranked or bold. Generated from the rows, never typed."""
    lines = ["# Leaderboard", "",
             f"Generated by `{WRITER}` from the bench rows in `results/bench/` (never typed).",
             "Each row: `zodrive bench POLICY --scenario S` under the protocol named in its table's title",
             "([docs/bench.md](bench.md)). Return under attack at ε is the worst black-box attack of the ensemble",
             "at that ε or any smaller one (no perturbation included: every such point is inside the ε-ball);",
             "PGD (white-box, needs gradients) is a separate column. Ranked by the return at the largest ε.",
             "ε past brake: the smallest ε at which the policy collides more often than the constant brake does",
             "clean (0: already clean). Δ closest constant: clean return minus that of the constant action (a",
             "`baseline:` row of the same table) it beats by the least, paired on the same seeds (95% CI); a policy",
             "beats every constant action by a margin its CI shows where the low end is above 0 (its margin in",
             "bold). Queries to crash: the median, over the attacked episodes that crashed, of the victim queries",
             "the attack spent in the episode. Rows marked † load their network with SB3's own loader",
             "(`--trust-model`: code of the model's author, which zodrive does not rebuild). Rows benched with",
             "fewer episodes than the protocol's (`--episodes`) are unofficial: they stand in a table of their own",
             "under each ranked table, never ranked, never bold. Defense: what stands between the sensor and the",
             "policy in a defended row (`zodrive bench MODEL --defense NAME`); its attacks query the defended",
             "system, and its ensemble adds the attacks that adapt to that defense (docs/bench.md). Exact attackable:",
             "of a sample of the row's clean states (said under the table), those where some perturbation inside the",
             "ε-ball changes the action, decided by a complete check of the network (`zodrive certify MODEL --row",
             "FOLDER`; ReLU MLPs); ensemble miss: of those, the ones no black-box attack of the ensemble changed (PGD",
             "not counted); – where a row has no such check (docs/bench.md, \"The exact check\").", ""]
    def table(r: dict[str, Any]) -> tuple[str, str, str]:
        return r["scenario"], r.get("track") or DENSE, r["protocol"]

    # rows of two versions or two tracks never share a table; a scenario's tracks follow its dense table
    for place, track, proto in sorted({table(r) for r in rows}, key=lambda t: (t[0], not is_dense(t[1]), t[1], t[2])):
        group = sorted((r for r in rows if table(r) == (place, track, proto)),
                       key=lambda r: (-r["attacked"][-1]["return"], -r["clean"]["return"]))
        where = place if is_dense(track) else f"{place}, track {track}"
        title = f"## {where} (protocol {proto})"
        current = PROTOCOLS.get(place) if is_dense(track) else TRACK_PROTOCOLS.get((place, track))
        if current is not None and proto != current.name():
            title += (f" — an earlier version: `zodrive bench` with each row's own command runs it under "
                      f"{current.name()}, reusing its finished cells")
        lines += [title, ""]
        if not is_dense(track):
            lines += _threat_model(track, current_protocols().get(proto))
        official = [r for r in group if r["official"]]
        unofficial = [r for r in group if not r["official"]]
        if official:
            lines += _table(official, ranked=True)
            lines += exact_notes(official)
            lines += _identical(official)
            lines += _defended(official)
        if unofficial:
            lines += [f"Unofficial rows of {where} (fewer episodes than the protocol's: not ranked, no margin in "
                      "bold; their CIs are wide):", ""]
            lines += _table(unofficial, ranked=False)
            lines += exact_notes(unofficial)
    return "\n".join(lines)


def _threat_model(track: str, proto: Protocol | None) -> list[str]:
    """A track's threat model under its table's heading, with each ε in metres and m/s (`physical_eps`), for a
    protocol this zodrive knows (an unknown one: its name alone, in the heading)."""
    if proto is None or track not in TRACKS:
        return []
    units = "; ".join(f"ε {eps}: " + ", ".join(f"{f} {v:g} {'m/s' if f.startswith('v') else 'm'}"
                                               for f, v in moved.items())
                      for eps, moved in physical_eps(proto).items())
    cap = f"; at most {proto.query_budget} queries a step for a black-box attack" if proto.query_budget else ""
    return [f"Threat model: {TRACKS[track].threat}. Per ε, how far a feature may move: {units}{cap} "
            f"(`zodrive bench MODEL --scenario {proto.scenario} --track {track}`; docs/bench.md, \"Tracks\").", ""]


def _table(group: list[dict[str, Any]], *, ranked: bool) -> list[str]:
    """The Markdown table of `group`; the attacked columns beside the clean return of the same episodes
    where the clean figures come from more episodes (so no attacked column is read against another set)."""
    eps = [p["eps"] for p in group[0]["attacked"]]
    n, n_clean = group[0]["episodes"], group[0].get("clean_episodes", group[0]["episodes"])
    split = n_clean > n
    lines: list[str] = []
    if split:
        lines += [(f"Clean columns and Δ: {n_clean} episodes; \"Clean, first {n}\", the attacked columns, area and ε "
                   f"past brake: the first {n} (`clean_on_attacked_episodes`)."), ""]
    lines += ["| " + ("# | " if ranked else "")
              + "Policy | Defense | Clean return (95% CI) | Δ closest constant (paired 95% CI) | "
              "Collisions | Speed (m/s) | " + (f"Clean, first {n} | " if split else "")
              + " | ".join(f"ε {e:g}: return / collisions" for e in eps)
              + f" | PGD ε {eps[-1]:g} | Area | ε past brake | Queries to crash (median) | "
              + " | ".join(exact_headers(eps)) + " |",
              "|---" * (12 + len(eps) + int(ranked) + int(split)) + "|"]
    for rank, r in enumerate(group, 1):
        c = r["clean"]
        cells = [f"{p['return']:.2f} / {100 * p['collision_rate']:.0f}%" for p in r["attacked"]]
        last = r["attacked"][-1]
        pgd = "–" if last["pgd_return"] is None else f"{last['pgd_return']:.2f}"
        q = next((p["queries_to_crash"] for p in r["attacked"] if p["queries_to_crash"] is not None), None)
        delta = _closest_constant(r, bold=ranked)
        marks = "†" if r.get("trust_model") else ""
        same = r.get("clean_on_attacked_episodes") or c
        past = ("the brake" if r.get("key") == BRAKE else "–"
                if r["eps_collisions_pass_brake"] is None else format(r["eps_collisions_pass_brake"], "g"))
        lines.append("| " + (f"{rank} | " if ranked else "") + f"{r['policy']}{marks} | {r.get('defense') or '–'} | "
                     f"{c['return']:.2f} "
                     f"({c['ci95'][0]:.2f}–{c['ci95'][1]:.2f}) | {delta} | {100 * c['collision_rate']:.0f}% | "
                     f"{c['speed']:.1f} | " + (f"{same['return']:.2f} / {100 * same['collision_rate']:.0f}% | "
                                               if split else "")
                     + " | ".join(cells) + f" | {pgd} | "
                     f"{'–' if r['robustness_area'] is None else format(r['robustness_area'], '.2f')} | {past} | "
                     f"{'–' if q is None else format(q, ',.0f')} | " + " | ".join(exact_cells(r)) + " |")
    lines.append("")
    return lines


def _defended(group: list[dict[str, Any]]) -> list[str]:
    """The defended rows of a table against their policy undefended: what the defense costs clean and what
    it changes under the strongest attack at the largest ε, paired on the same episodes."""
    pairs = [r for r in group if r.get("vs_undefended")]
    if not pairs:
        return []

    def diff(m: list[float] | None) -> str:
        return "–" if m is None else f"{m[0]:+.2f} ({m[1]:+.2f} to {m[2]:+.2f})"

    eps = pairs[0]["vs_undefended"]["eps"]
    lines = ["Defended rows against their policy undefended (defended minus undefended, paired on the same episodes, "
             "95% CI): clean over the clean episodes, and under the strongest attack each row kept at the largest ε.",
             "", f"| Row | Defense | Undefended row | Clean Δ | ε {eps:g} Δ |", "|---|---|---|---|---|"]
    for r in pairs:
        m = r["vs_undefended"]
        lines.append(f"| {r['policy']} | {r['defense']} | {m['policy']} | {diff(m['clean'])} | {diff(m['attacked'])} |")
    return lines + [""]


def _identical(group: list[dict[str, Any]]) -> list[str]:
    """A sentence for rows whose clean and attacked figures are all equal: two policies that drove the same
    episodes (on intersection and merge, always-FASTER and always-IDLE do), said, not left to be noticed."""
    def figures(r: dict[str, Any]) -> str:
        return json.dumps([r["clean"], r["attacked"]], sort_keys=True, default=str)

    seen: dict[str, list[str]] = {}
    for r in group:
        seen.setdefault(figures(r), []).append(r["policy"])
    same = [names for names in seen.values() if len(names) > 1]
    return [f"{' and '.join(names)} score alike in every column here (the same return, collisions and speed on every "
            "episode set): on these seeds they drove the same." for names in same] + ([""] if same else [])


def _closest_constant(row: dict[str, Any], *, bold: bool = True) -> str:
    """The paired margin over the constant action with the lowest CI end (the brake's, from the row's
    own cells, where no constant is on the board), in bold where that end is above 0; "–" where none
    is on the same seeds."""
    margins = {name: m for name, m in row.get("vs_constants", {}).items() if m is not None}
    if not margins and row.get("vs_brake") is not None:
        margins = {BRAKE.removeprefix(PREFIX): row["vs_brake"]}
    if not margins:
        return "–"
    name, (mean, low, high) = min(margins.items(), key=lambda item: item[1][1])
    shown = f"**{mean:+.2f}**" if low > 0 and bold else f"{mean:+.2f}"  # bold: beats every constant by its CI
    return f"{shown} ({low:+.2f} to {high:+.2f}) vs {name}"


WRITER = "zodrive leaderboard"
"""What the leaderboard's files carry (the Markdown's first lines, the PNG's Software field): a file that
does not is someone else's, and is replaced only with --force."""


def write_leaderboard(board: Path, out: Path, plot: Path | None = None, *, frontier: Path | None = None,
                      force: bool = False) -> str:
    rows = read_rows(board)
    if not rows:
        raise ZodriveError(f"no bench rows under {board} (expected {board}/SCENARIO/POLICY/row.json)")
    for path in (out, plot, frontier):
        if path is not None and path.exists() and not force and not written_by_zodrive(path):
            raise ZodriveError(f"{path} exists and was not written by `{WRITER}`: pass --force to replace it")
    text = leaderboard_markdown(rows)
    write_atomic(out, text)
    if plot is not None:
        plot_leaderboard(rows, plot)
    if frontier is not None:
        plot_frontier(rows, frontier)
    return text


def written_by_zodrive(path: Path) -> bool:
    """Whether `path` is a leaderboard file zodrive wrote (read only its first 64 KiB: nothing is trusted)."""
    if not path.is_file():
        return False
    with path.open("rb") as f:
        head = f.read(65536)
    return head.startswith(b"# Leaderboard\n") and f"Generated by `{WRITER}`".encode() in head[:400] \
        or head.startswith(b"\x89PNG") and WRITER.encode() in head


MARKERS = "osD^v<>"


def family_and_seed(policy: str) -> tuple[str, int]:
    """A row's family and seed: ('dqn-g99', 1) for 'dqn-g99-seed-1', (policy, 0) for a row without one."""
    family, sep, seed = policy.rpartition("-seed-")
    return (family, int(seed)) if sep and seed.isdigit() else (policy, 0)


def _constant(row: dict[str, Any]) -> bool:
    """A constant action (reads nothing): drawn dashed and grey, as a floor, not as a policy."""
    key = str(row.get("key", ""))
    return key.startswith(PREFIX) and key.removeprefix(PREFIX) in BASELINES \
        and BASELINES[key.removeprefix(PREFIX)].reads == "nothing"


def family_colours(families: list[str]) -> dict[str, int]:
    """A colour index of tab20 per family that does not change when another row is added: each family's
    own hue (a hash of its name; tab20's dark shades), the next free hue where two families of one panel
    share one, light shades only past ten families."""
    order = [*range(0, 20, 2), *range(1, 20, 2)]  # ten distinct hues, then their light shades
    taken: dict[str, int] = {}
    for family in sorted(families, key=lambda f: (hash_slot(f, 10), f)):
        slot = hash_slot(family, 10)
        while order[slot % 20] in taken.values() and len(taken) < 20:
            slot += 1
        taken[family] = order[slot % 20]
    return taken


def line_style(row: dict[str, Any], colours: dict[str, int]) -> dict[str, Any]:
    """How a row is drawn: a colour per family (its index in tab20), a marker per seed; the constant
    actions dashed, in grey shades, whatever their number."""
    family, seed = family_and_seed(row["policy"])
    if _constant(row):
        return {"color": ("0.15", "0.45", "0.7")[hash_slot(family, 3)], "marker": "x", "linestyle": "--"}
    return {"color": colours[family], "marker": MARKERS[seed % len(MARKERS)], "linestyle": "-"}


def hash_slot(name: str, n: int) -> int:
    import zlib

    return zlib.crc32(name.encode()) % n


def plot_leaderboard(rows: list[dict[str, Any]], path: Path) -> None:
    """Return against ε per scenario (worst black-box attack), one line per row, a colour per family that
    stays when rows are added; unofficial rows dotted and faded, named so in the legend."""
    from zodrive.evaluation.report import headless_pyplot

    plt = headless_pyplot()
    shown = rows
    protocols = sorted({r["protocol"] for r in shown})  # one panel per table of the leaderboard
    fig, axes = plt.subplots(1, len(protocols), figsize=(4.2 * len(protocols), 5.6), squeeze=False)
    palette = plt.get_cmap("tab20")
    for ax, name in zip(axes[0], protocols):
        table = sorted((r for r in shown if r["protocol"] == name), key=lambda r: r["policy"])
        colours = family_colours(sorted({family_and_seed(r["policy"])[0] for r in table if not _constant(r)}))
        for r in table:
            eps = [0.0, *(p["eps"] for p in r["attacked"])]  # ε 0: the clean return of the attacked episodes
            ret = [r.get("clean_on_attacked_episodes", r["clean"])["return"], *(p["return"] for p in r["attacked"])]
            style = line_style(r, colours)
            if not isinstance(style["color"], str):
                style["color"] = palette(style["color"])
            label = r["policy"]
            if not r["official"]:  # a quick look: dotted, faded, and said in the legend
                style.update(linestyle=":", alpha=0.55)
                label += f" (unofficial, {r['episodes']} ep.)"
            ax.plot(eps, ret, lw=1.2, ms=4, label=label, **style)
        ax.set_title(f"{table[0]['scenario']} ({name})", fontsize=9)
        ax.set_xlabel("ε (L∞, normalized observation)")
        ax.set_ylabel("mean episode return\n(worst black-box attack at ≤ ε; ε 0: clean)", fontsize=8)
        ax.legend(fontsize=6, ncol=2, loc="upper center", bbox_to_anchor=(0.5, -0.2))
    fig.suptitle("zodrive leaderboard (dashed grey: constant actions; dotted: unofficial rows)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120, metadata={"Software": WRITER})
    plt.close(fig)


def pareto(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the points no other point beats on both coordinates (higher is better), by the first."""
    keep = [i for i, (x, y) in enumerate(points)
            if not any((a >= x and b >= y) and (a, b) != (x, y) for a, b in points)]
    return sorted(keep, key=lambda i: points[i])


def plot_frontier(rows: list[dict[str, Any]], path: Path) -> None:
    """Clean return against the return under the strongest attack at the largest ε, one panel per current
    protocol's table of official rows: which systems both drive well and hold up. Defended rows are squares,
    constant actions grey; the line joins the rows no other row beats on both."""
    from zodrive.evaluation.report import headless_pyplot

    plt = headless_pyplot()
    current = set(current_protocols())  # an earlier version's table is history, not a choice
    official = [r for r in rows if r["official"] and r["protocol"] in current]
    protocols = sorted({r["protocol"] for r in official})
    if not protocols:
        raise ZodriveError("no official bench rows of a current protocol: the frontier compares rows of the "
                           "protocols' episodes")
    fig, axes = plt.subplots(1, len(protocols), figsize=(4.6 * len(protocols), 4.6), squeeze=False)
    for ax, name in zip(axes[0], protocols):
        table = sorted((r for r in official if r["protocol"] == name), key=lambda r: r["policy"])
        points = [(r["clean"]["return"], r["attacked"][-1]["return"]) for r in table]
        for r, (x, y) in zip(table, points):
            ax.scatter([x], [y], marker="s" if r.get("defense") else "o", s=22, zorder=3,
                       color="0.55" if _constant(r) else ("C3" if r.get("defense") else "C0"))
            ax.annotate(r["policy"], (x, y), fontsize=5, xytext=(3, 2), textcoords="offset points")
        front = pareto(points)
        ax.plot([points[i][0] for i in front], [points[i][1] for i in front], color="C2", lw=1, zorder=2)
        ax.set_title(f"{table[0]['scenario']} ({name})", fontsize=9)
        ax.set_xlabel("clean return (protocol's clean episodes)", fontsize=8)
        ax.set_ylabel(f"return at ε {table[0]['attacked'][-1]['eps']:g}\n(worst black-box attack)", fontsize=8)
    fig.suptitle("zodrive frontier: clean against attacked (squares: defended; grey: constant actions; "
                 "line: no row beats these on both)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=130, metadata={"Software": WRITER})
    plt.close(fig)
