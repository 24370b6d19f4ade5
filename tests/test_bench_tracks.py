"""The bench's tracks (issue 65, item 4): each a protocol of its own, its cells under its threat model, its rows
in a folder and a table of their own, and an oracle that never sees a point outside the track's threat model."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from toys import context, linear_victim, logging_victim, observations
from zodrive.attacks import AttackSpec
from zodrive.attacks.oracle import QueryOracle
from zodrive.attacks.registry import ATTACKS
from zodrive.attacks.victim import Victim
from zodrive.bench.bench import (
    BLACK_BOX,
    PROTOCOLS,
    QUERY_CAP,
    TRACK_PROTOCOLS,
    WHITE_BOX,
    brake_folder,
    current_protocols,
    protocol,
    row_folder,
)
from zodrive.bench.leaderboard import leaderboard_markdown, read_rows
from zodrive.bench.tracks import DENSE, TRACK_SCENARIOS, TRACKS
from zodrive.cli import main
from zodrive.errors import ZodriveError
from zodrive.evaluation import store
from zodrive.system import Attacker, Schedule

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "models" / "ppo-highway-fast"  # a policy with gradients: its rows have the PGD column
EPS = 0.3  # the toy's radius: wide enough that every attack moves the toy victim's observations
STEPS = 30  # one highway-fast episode's decisions


def test_each_track_is_a_protocol_with_an_id_and_a_version_of_its_own() -> None:
    assert protocol("highway-fast", "one-object").name() == "highway-fast-one-object-v1"
    assert protocol("merge", "decision").name() == "merge-decision-v1"
    assert protocol("highway-fast", "sparse").name() == "highway-fast-sparse-v1"
    assert protocol("highway-fast") is protocol("highway-fast", DENSE) is PROTOCOLS["highway-fast"]
    ids = [p.name() for p in (*PROTOCOLS.values(), *TRACK_PROTOCOLS.values())]
    assert len(set(ids)) == len(ids) == len(current_protocols())  # rows of two tracks never share an id
    for scenario in TRACK_SCENARIOS:  # a track changes the threat model and nothing else of its scenario's grid
        dense = PROTOCOLS[scenario]
        for name in TRACKS:
            track = protocol(scenario, name)
            assert (track.seed, track.episodes, track.clean_episodes, track.eps) == \
                (dense.seed, dense.episodes, dense.clean_episodes, dense.eps), (scenario, name)
            assert track.query_budget == QUERY_CAP and track.track == name and track.version == 1
    decision = protocol("highway-fast", "decision")
    assert decision.white_box is None and "hsja" in decision.black_box  # no gradient for a decision-only attacker
    assert all(ATTACKS[a].on_decisions for a in decision.black_box) and "zo-signsgd" not in decision.black_box
    for name in ("one-object", "sparse"):
        assert (protocol("merge", name).black_box, protocol("merge", name).white_box) == (BLACK_BOX, WHITE_BOX)
    assert protocol("highway-fast", "one-object").attack_set == ("vehicles=1",)
    assert protocol("highway-fast", "sparse").attack_set == ("attack_share=0.1", "when=every")
    with pytest.raises(ZodriveError, match="scenario roundabout has no sparse track"):
        protocol("roundabout", "sparse")
    with pytest.raises(ZodriveError, match="no bench track 'spare'"):
        protocol("highway-fast", "spare")


def test_a_tracks_rows_have_a_folder_of_their_own_and_read_the_scenarios_brake(tmp_path: Path) -> None:
    dense = row_folder(tmp_path, "highway-fast", "dqn")
    track = row_folder(tmp_path, "highway-fast", "dqn", "one-object")
    assert dense == tmp_path / "highway-fast" / "dqn"
    assert track == tmp_path / "highway-fast" / "tracks" / "one-object" / "dqn"
    # the brake reads nothing: one per scenario and seed set, for every track
    assert brake_folder(dense) == brake_folder(track, "one-object") == tmp_path / "highway-fast" / "brake"


def test_a_track_row_starts_from_its_dense_rows_clean_cells(tmp_path: Path) -> None:
    """The clean cells of a track row are the dense row's evaluation (no attack): copied, never run twice; but
    only from the same policy's finished row of the same episode counts (nothing is run here)."""
    from zodrive.bench.tracks import share_clean

    dense = ROOT / "results" / "bench" / "highway-fast" / "baseline-slower"
    out = row_folder(tmp_path, "highway-fast", "baseline-slower", "sparse")
    assert share_clean("baseline:faster", "highway-fast", 100000, dense, out, (100, 300)) == []  # another policy
    assert share_clean("baseline:slower", "highway-fast", 100000, dense, out, (2, 2)) == []  # another row's counts
    copied = share_clean("baseline:slower", "highway-fast", 100000, dense, out, (100, 300))
    assert copied == [out / "cells" / "baseline-slower-none", out / "clean" / "cells" / "baseline-slower-none"]
    for cell in copied:
        mine = [json.loads(line) for line in (cell / "episodes.jsonl").read_text().splitlines()]
        assert mine == store.episodes(dense / cell.relative_to(out))  # the dense cell, a folder or packed
        assert not (cell / "summary.json").exists()  # the evaluation makes it again from the episodes
    assert len((out / "clean" / "cells" / "baseline-slower-none" / "episodes.jsonl").read_text().splitlines()) == 300
    assert share_clean("baseline:slower", "highway-fast", 100000, dense, out, (100, 300)) == []  # never over a cell


@pytest.fixture(scope="module")
def track_cells(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[Any]]:
    """Per track, the cells `bench` would run for a policy with gradients (nothing is run)."""
    import zodrive.experiments.compare as compare_module
    from zodrive.bench.bench import bench

    class Planned(Exception):
        pass

    cells: dict[str, list[Any]] = {}
    real = compare_module.run_cells
    board = tmp_path_factory.mktemp("board")
    try:
        for name in TRACKS:
            def plan(planned: list[Any], track: str = name, **kwargs: Any) -> None:
                cells[track] = planned
                raise Planned

            compare_module.run_cells = plan  # type: ignore[assignment]
            with pytest.raises(Planned):
                bench(str(MODEL), protocol("highway-fast", name), row_folder(board, "highway-fast", "ppo", name),
                      progress=False)
    finally:
        compare_module.run_cells = real
    return cells


def _attacked(cells: list[Any]) -> dict[str, AttackSpec]:
    """The attacked cells' specs by folder name."""
    return {c.folder.name: c.job.attack for c in cells if c.job.attack is not None}


def test_a_tracks_cells_carry_its_threat_model(track_cells: dict[str, list[Any]]) -> None:
    for name, cells in track_cells.items():
        assert [c.job.attack for c in cells if c.folder.name.endswith("-none")] == [None]  # the clean cell
        specs = _attacked(cells)
        assert {s.attack for s in specs.values()} == {*protocol("highway-fast", name).black_box,
                                                      *([WHITE_BOX] if name != "decision" else [])}
        assert len(specs) == 3 * len({s.attack for s in specs.values()})  # every attack at every eps of the grid
        for spec in specs.values():  # the cap binds the black-box attacks as in version 4, not PGD
            assert spec.query_budget == (None if spec.attack == WHITE_BOX else QUERY_CAP)
    assert all(s.vehicles == 1 and s.access == "score" and s.attack_share == 1
               for s in _attacked(track_cells["one-object"]).values())
    assert all(s.attack_share == 0.1 and s.when == "every" and s.vehicles is None and s.access == "score"
               for s in _attacked(track_cells["sparse"]).values())
    assert all(s.access == "decision" and s.vehicles is None and s.attack_share == 1
               for s in _attacked(track_cells["decision"]).values())
    assert "pgd" not in {s.attack for s in _attacked(track_cells["decision"]).values()}


def _rows_moved(points: np.ndarray, clean: np.ndarray) -> np.ndarray:
    return np.any(points != clean, axis=-1).sum(axis=-1)


@pytest.mark.parametrize("track", list(TRACKS))
def test_the_oracle_never_sees_a_point_outside_the_tracks_threat_model(
        track: str, track_cells: dict[str, list[Any]], monkeypatch: pytest.MonkeyPatch) -> None:
    """Each attack of a track's row, as the bench configures it (at the toy's radius), through one episode of
    30 decisions: every row the victim is asked about, by query or for a gradient, and every row it acts on,
    is inside the track's threat model; and what the oracle answers a decision-only attacker is decisions."""
    answers: list[np.ndarray] = []
    call = QueryOracle.__call__

    def spy(self: QueryOracle, batch: np.ndarray, owners: np.ndarray | None = None) -> np.ndarray:
        answers.append(call(self, batch, owners))
        return answers[-1]

    monkeypatch.setattr(QueryOracle, "__call__", spy)
    if track == "decision":
        monkeypatch.setattr(QueryOracle, "gradient", lambda *a, **k: pytest.fail("a gradient on decision access"))
    specs = {s.attack: s for s in _attacked(track_cells[track]).values() if s.eps == max(protocol("highway-fast").eps)}
    clean = observations(STEPS, seed=11)
    for name, spec in sorted(specs.items()):
        spec = spec.with_overrides(eps=EPS)
        network = linear_victim(seed=2)
        queried: list[np.ndarray] = []
        graded: list[np.ndarray] = []

        def differentiable(x: Any, network: Victim = network, graded: list[np.ndarray] = graded) -> Any:
            graded.append(x.detach().numpy().copy())
            return network.differentiable(x)  # type: ignore[misc]

        victim = Victim(query=network.query, kind="discrete", obs_shape=(5, 5), differentiable=differentiable,
                        calibrate=network.calibrate)
        attacker = Attacker(*spec.build(logging_victim(victim, queried), **context()), schedule=Schedule.of(spec))
        attacker.start([100000])
        asked: list[list[np.ndarray]] = []
        fed = []
        for t in range(STEPS):  # an episode, one decision at a time as the bench plays a sparse track's
            start = len(queried), len(graded)
            result, _ = attacker.step(clean[t][None])
            asked.append([*queried[start[0]:], *graded[start[1]:]])
            fed.append(result.x_adv[0])
        assert sum(map(len, queried)) + sum(map(len, graded)) == attacker.oracle.total_queries > 0  # the logs saw all
        moved = False
        for t in range(STEPS):
            points = np.concatenate([b.reshape(-1, 5, 5) for b in asked[t]] + [fed[t][None]])
            delta = np.abs(points - clean[t])
            assert delta.max() <= EPS + 1e-5 and points.min() >= -1 and points.max() <= 1, (name, t)
            np.testing.assert_array_equal(points[..., 0], np.broadcast_to(clean[t][:, 0], points[..., 0].shape))
            moved |= bool(delta.max() > 0)
            if track == "one-object":
                assert _rows_moved(points, clean[t]).max() <= 1, (name, t)
            if track == "sparse" and (t + 1) % 10:  # steps 9, 19 and 29 attacked; the others clean, unasked
                assert asked[t] == [] and np.array_equal(fed[t], clean[t]), (name, t)
        assert moved, name  # the attack did move the observation: the checks above bound something
        if track == "sparse":
            assert all(asked[t] for t in (9, 19, 29)), name
        if track == "decision":
            outputs = np.concatenate(answers)
            assert np.all((outputs == 0) | (outputs == 1)) and np.all(outputs.sum(axis=-1) == 1), name
        answers.clear()


def _row(template: dict[str, Any], policy: str, protocol_id: str, track: str | None = None) -> dict[str, Any]:
    row = {**template, "policy": policy, "protocol": protocol_id}
    if track is not None:
        row["track"] = track
    return row


def test_the_leaderboard_gives_each_track_a_table_of_its_own_with_its_threat_model(tmp_path: Path) -> None:
    template = json.loads((ROOT / "results" / "bench" / "highway-fast" / "baseline-slower" / "row.json").read_text())
    board = tmp_path / "board"
    rows = {row_folder(board, "highway-fast", "dense-row"): _row(template, "dense-row", "highway-fast-v4"),
            row_folder(board, "highway-fast", "object-row", "one-object"):
                _row(template, "object-row", "highway-fast-one-object-v1", "one-object"),
            row_folder(board, "highway-fast", "decision-row", "decision"):
                _row(template, "decision-row", "highway-fast-decision-v1", "decision")}
    for folder, row in rows.items():
        folder.mkdir(parents=True)
        (folder / "row.json").write_text(json.dumps(row))
    read = read_rows(board)
    assert sorted((r["policy"], r.get("track")) for r in read) == [
        ("decision-row", "decision"), ("dense-row", None), ("object-row", "one-object")]
    text = leaderboard_markdown(read)
    dense = text.index("## highway-fast (protocol highway-fast-v4)\n")
    decision = text.index("## highway-fast, track decision (protocol highway-fast-decision-v1)\n")
    one = text.index("## highway-fast, track one-object (protocol highway-fast-one-object-v1)\n")
    assert dense < text.index("| dense-row |") < decision < text.index("| decision-row |") < one \
        < text.index("| object-row |")  # the dense table first, then each track's, each with its own rows
    threat = text[one:].splitlines()[2]
    assert threat.startswith("Threat model: one object: at most one vehicle row")
    assert "ε 0.05: vx 4 m/s, vy 4 m/s, x 10 m, y 0.6 m" in threat and "at most 500 queries a step" in threat
    assert "--track one-object" in threat
    assert "no white-box PGD" in text[decision:one]


def test_a_track_row_of_an_earlier_version_is_said_so() -> None:
    template = json.loads((ROOT / "results" / "bench" / "highway-fast" / "baseline-slower" / "row.json").read_text())
    text = leaderboard_markdown([_row(template, "old", "highway-fast-sparse-v0", "sparse"),
                                 _row(template, "new", "highway-fast-sparse-v1", "sparse")])
    assert "## highway-fast, track sparse (protocol highway-fast-sparse-v0) — an earlier version" in text
    assert "## highway-fast, track sparse (protocol highway-fast-sparse-v1)\n" in text


def test_the_exact_check_refuses_a_track_row(tmp_path: Path) -> None:
    from zodrive.bench.exact_row import certify_row

    template = json.loads((ROOT / "results" / "bench" / "highway-fast" / "dqn-seed-0" / "row.json").read_text())
    (tmp_path / "row.json").write_text(json.dumps(_row(template, "dqn", "highway-fast-one-object-v1", "one-object")))
    with pytest.raises(ZodriveError, match="a row of the one-object track"):
        certify_row(str(ROOT / "models" / "zoo" / "highway-fast-dqn" / "seed-0"), tmp_path)


@pytest.mark.parametrize("args, message", [
    (["--scenario", "highway-fast", "--track", "spares"], "argument --track: invalid choice: 'spares'"),
    (["--scenario", "roundabout", "--track", "sparse"], "scenario roundabout has no sparse track"),
    (["--scenario", "discrete", "--track", "decision"], "scenario discrete has no decision track"),
    (["--scenario", "highway-fast", "--track", "one-object", "--defense", "shield@0.02"],
     "--defense with --track one-object: a defended row is benched on the dense track"),
    (["--scenario", "merge", "--track", "sparse", "--name", "tracks"], "--name tracks: the board's own folder"),
    (["--scenario", "merge", "--name", "brake"], "--name brake: the board's own folder"),
])
def test_a_bench_on_a_track_refuses_bad_input_in_one_line(args: list[str], message: str, tmp_path: Path, capsys,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    import zodrive.bench.bench as bench_module

    monkeypatch.setattr(bench_module, "compare", lambda *a, **k: pytest.fail("a refused bench ran a cell"))
    assert main(["bench", "baseline:rules", *args, "--board", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err
    assert not any(tmp_path.iterdir())


@pytest.mark.integration
def test_a_track_row_shares_the_brake_and_the_dense_rows_clean_cells(tmp_path: Path, monkeypatch) -> None:
    """On real highway-env episodes: the track's row runs no clean episode its dense row has run, and none of the
    brake's; its row says its track and threat model, and the leaderboard gives it its own table."""
    import zodrive.evaluation.evaluate as evaluation

    common = ["--scenario", "highway-fast", "--episodes", "1", "--board", str(tmp_path), "--no-progress"]
    assert main(["bench", "baseline:idle", *common]) == 0
    ran: list[tuple[str, Any]] = []
    real = evaluation.run_episodes
    monkeypatch.setattr(evaluation, "run_episodes", lambda job, indices, *a, **k: (
        indices and ran.append((job.model.ref, job.attack)), real(job, indices, *a, **k))[1])
    assert main(["bench", "baseline:idle", *common, "--track", "one-object"]) == 0
    assert ran == []  # the idle driver reads nothing: its clean cell is the dense row's, and the brake is the board's
    folder = tmp_path / "highway-fast" / "tracks" / "one-object" / "baseline-idle"
    row = json.loads((folder / "row.json").read_text())
    assert row["protocol"] == "highway-fast-one-object-v1" and (row["track"], row["threat"]) == ("one-object",
                                                                                                  {"vehicles": 1})
    dense = json.loads((tmp_path / "highway-fast" / "baseline-idle" / "row.json").read_text())
    assert row["clean"] == dense["clean"] and row["brake"] == dense["brake"]
    assert not (folder / "brake").exists() and not (folder.parent / "brake").exists()
    assert "## highway-fast, track one-object (protocol highway-fast-one-object-v1)" in \
        (tmp_path / "leaderboard.md").read_text()
