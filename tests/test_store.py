"""Packed evaluation folders (`zodrive pack`, `zodrive.evaluation.store`): byte for byte, read by the same
readers as a folder, and a grid resumes over them without running a finished cell again."""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import pytest

from zodrive.cli import main
from zodrive.errors import ZodriveError
from zodrive.evaluation import store
from zodrive.runinfo import to_json, write_atomic, write_json


def _evaluation(folder: Path, episodes: int, *, finished: bool = True, steps: bool = False) -> dict[str, bytes]:
    """An evaluation folder as `evaluate` writes one; its files' bytes."""
    write_json(folder / "eval_key.json", {"model": "baseline:slower", "seed": 100000, "attack": None})
    write_atomic(folder / "episodes.jsonl", "".join(to_json({"episode": i, "return": 1.5 * i, "crashed": i == 1,
                                                                "seed": 100000 + i}) + "\n" for i in range(episodes)))
    if finished:
        write_json(folder / "summary.json", {"episodes": episodes, "mean_return": 0.75, "ci95": [0.0, 1.5]})
    if steps:
        write_atomic(folder / "steps.jsonl", '{"episode": 0, "t": 0}\n')
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.name != "steps.jsonl"}


def test_a_pack_gives_back_every_byte_and_reads_as_the_folders(tmp_path: Path, capsys) -> None:
    cells = tmp_path / "grid" / "cells"
    files = {"a-none": _evaluation(cells / "a-none", 3, steps=True), "b-none": _evaluation(cells / "b-none", 2)}
    _evaluation(cells / "c-cut", 3, finished=False)  # unfinished: left live
    _evaluation(cells / "d-mine", 1)
    (cells / "d-mine" / "notes.txt").write_text("mine\n")  # a file a pack does not keep: left live
    (cells / "e-mine").mkdir()
    (cells / "e-mine" / "notes.txt").write_text("not an evaluation\n")
    before = {name: store.read(cells / name) for name in files}
    assert main(["pack", str(tmp_path / "grid")]) == 0
    out = capsys.readouterr().out
    pack = tmp_path / "grid" / "cells.jsonl.gz"
    assert f"packed 2 evaluation folders into {pack}" in out
    assert "c-cut: unfinished: no summary" in out and "d-mine: holds notes.txt, which a pack does not keep" in out
    assert not (cells / "a-none").exists() and not (cells / "b-none").exists() and (cells / "c-cut").is_dir()
    lines = [json.loads(line) for line in gzip.decompress(pack.read_bytes()).decode().splitlines()]
    assert [r["cell"] for r in lines] == ["a-none", "b-none"] and set(lines[0]) == {"cell", "eval_key", "summary",
                                                                                    "episodes"}
    for name, found in before.items():  # every reader reads the pack as it read the folder
        packed = store.read(cells / name)
        assert packed.packed and (packed.key, packed.summary, packed.episodes) == (found.key, found.summary,
                                                                                    found.episodes)
    assert [p.name for p in store.names(cells, "*-none")] == ["a-none", "b-none"]
    assert [p.name for p in store.names(cells)] == ["a-none", "b-none", "c-cut", "d-mine"]  # e-mine: no evaluation
    assert store.summary(cells / "a-none", ("mean_return",))["mean_return"] == 0.75
    assert sorted(str(p.relative_to(tmp_path)) for p in store.walk(tmp_path)) == [
        "grid/cells/a-none", "grid/cells/b-none", "grid/cells/c-cut"]
    (cells / "a-none").mkdir()  # a checkout that moved to the pack leaves a cell's git-ignored steps.jsonl behind
    (cells / "a-none" / "steps.jsonl").write_text('{"episode": 0, "t": 0}\n')
    assert store.read(cells / "a-none").packed and [p.name for p in store.names(cells, "a-*")] == ["a-none"]
    assert main(["pack", str(tmp_path / "grid")]) == 0  # again: nothing more to pack, the same bytes
    assert pack.read_bytes() == gzip.compress(gzip.decompress(pack.read_bytes()), compresslevel=9, mtime=0)
    assert main(["pack", "--unpack", str(tmp_path / "grid")]) == 0
    assert not pack.exists()
    for name, kept in files.items():  # byte for byte (steps.jsonl, git-ignored, is not kept)
        assert {p.name: p.read_bytes() for p in (cells / name).iterdir() if p.name != "steps.jsonl"} == kept


def test_a_folder_not_in_zodrive_s_layout_is_not_packed(tmp_path: Path) -> None:
    folder = tmp_path / "cells" / "x-none"
    _evaluation(folder, 1)
    (folder / "summary.json").write_text('{"episodes": 1,   "mean_return": 0.0}\n')  # hand-edited spacing
    done = store.pack(tmp_path / "cells")
    assert done.packed == [] and "not in zodrive's own JSON layout" in done.left["x-none"]
    assert folder.is_dir() and not (tmp_path / "cells.jsonl.gz").exists()


def test_a_damaged_pack_is_one_line(tmp_path: Path, capsys) -> None:
    pack = tmp_path / "cells.jsonl.gz"
    for data, says in ((b"not gzip", "is damaged (not gzip)"),
                       (gzip.compress(b'{"episodes": []}\n'), "line 1 is not a packed evaluation"),
                       (gzip.compress(b'{"cell": "../x"}\n'), "line 1 is not a packed evaluation"),
                       (gzip.compress(b'{"cell": "x", "episodes": 3}\n'), "cell 'x' is not a packed evaluation")):
        pack.write_bytes(data)
        store._lines.cache_clear()
        with pytest.raises(ZodriveError, match=r"^evaluation pack .*" + says.replace("(", r"\(").replace(")", r"\)")):
            store.read(tmp_path / "cells" / "x")
    with pytest.raises(ZodriveError, match="no cell 'y'"):
        store.read(tmp_path / "nowhere" / "y")
    assert main(["pack", str(tmp_path / "missing")]) == 2
    _evaluation(tmp_path / "cells" / "z", 1)
    assert main(["pack", str(tmp_path / "cells" / "z")]) == 2
    assert "is an evaluation folder: pack the folder that holds it" in capsys.readouterr().err


def test_a_grid_resumes_over_packed_cells(tmp_path: Path, monkeypatch) -> None:
    """A packed cell of the same key and episodes runs nothing; asked for more episodes, it gets its folder back
    and resumes from its episodes, as a folder would."""
    import zodrive.evaluation.evaluate as evaluation
    from zodrive.experiments.compare import compare

    out = tmp_path / "grid"
    first = compare(["baseline:slower", "baseline:idle"], [], [], 1, out, progress=False, preset="highway-fast",
                    envs=1)
    table = (out / "table.json").read_text()
    assert store.pack_tree(out)[0].packed == ["baseline-idle-none", "baseline-slower-none"]
    assert sorted(p.name for p in out.iterdir()) == ["cells.jsonl.gz", "grid.json", "table.csv", "table.json",
                                                     "table.md"]  # cells/ went with its last folder
    ran: list[list[int]] = []
    real = evaluation.run_episodes
    monkeypatch.setattr(evaluation, "run_episodes", lambda job, todo, *a, **k: (ran.append(list(todo)),
                                                                               real(job, todo, *a, **k))[1])
    assert compare(["baseline:slower", "baseline:idle"], [], [], 1, out, progress=False, preset="highway-fast",
                   envs=1) == first
    assert ran == [] and (out / "table.json").read_text() == table and not (out / "cells").exists()
    more = compare(["baseline:slower", "baseline:idle"], [], [], 2, out, progress=False, preset="highway-fast", envs=1)
    assert ran == [[1], [1]] and [r["episodes"] for r in more] == [2, 2]  # only the new episode of each cell
    assert sorted(p.name for p in (out / "cells").iterdir()) == ["baseline-idle-none", "baseline-slower-none"]
    assert not (out / "cells.jsonl.gz").exists()  # every line went back to its folder


def test_a_bench_row_reads_and_resumes_from_packed_cells(tmp_path: Path, monkeypatch) -> None:
    """The row, its brake and the leaderboard read a packed board as the folders it was packed from."""
    import zodrive.evaluation.evaluate as evaluation
    from zodrive.bench.bench import Protocol, bench
    from zodrive.bench.leaderboard import leaderboard_markdown, read_rows

    proto = Protocol("highway-fast", 1, (0.05,), clean_episodes=2, black_box=("uniform-noise",), white_box=None)
    board = tmp_path / "board"
    row = bench("baseline:rules", proto, board / "highway-fast" / "rules", name="rules", progress=False, envs=1)
    bench("baseline:slower", proto, board / "highway-fast" / "slower", name="slower", progress=False, envs=1)
    text = leaderboard_markdown(read_rows(board))
    packed = [p for done in store.pack_tree(board) for p in done.packed]
    assert len(packed) == 6 and not list(board.rglob("episodes.jsonl"))  # every cell, the brake's too
    assert sorted(str(p.relative_to(board)) for p in board.rglob("*.jsonl.gz")) == [
        "highway-fast/brake/cells.jsonl.gz", "highway-fast/rules/cells.jsonl.gz",
        "highway-fast/rules/clean/cells.jsonl.gz", "highway-fast/slower/cells.jsonl.gz",
        "highway-fast/slower/clean/cells.jsonl.gz"]
    assert leaderboard_markdown(read_rows(board)) == text

    def no_episode(*args, **kwargs):
        raise AssertionError("a finished cell ran again")

    monkeypatch.setattr(evaluation, "run_episodes", no_episode)
    assert bench("baseline:rules", proto, board / "highway-fast" / "rules", name="rules", progress=False,
                 envs=1) == row
    assert not list(board.rglob("episodes.jsonl"))


def _bench_grid(board: Path) -> dict[Path, str]:
    """A finished bench row of protocol highway-fast-v4 (`baseline:rules`, no gradients, would be too simple: a
    model `m` with PGD), its `clean/` and the board's brake, each cell's folder written as `evaluate` writes one and
    each `table.json` as `compare` writes it (the grid's order: clean, the ensemble, PGD last); the tables' text."""
    from zodrive.bench.bench import BLACK_BOX, QUERY_CAP, WHITE_BOX
    from zodrive.experiments.cells import GridCell
    from zodrive.experiments.compare import table_row, write_tables

    eps = (0.01, 0.02, 0.05)
    row = board / "highway-fast" / "m"
    grids = {row: ("models/m/model.zip", "observation", [GridCell("m")]
                   + [GridCell("m", a, e, QUERY_CAP) for a in BLACK_BOX for e in eps]
                   + [GridCell("m", WHITE_BOX, e, white_box=True) for e in eps]),
             row / "clean": ("models/m/model.zip", "observation", [GridCell("m")]),
             board / "highway-fast" / "brake": ("baseline:slower", "nothing", [GridCell("baseline:slower")])}
    for out, (model, reads, cells) in grids.items():
        episodes = 3 if out == row else 5
        rows = []
        for k, cell in enumerate(cells):
            folder = cell.folder(out)
            write_json(folder / "eval_key.json", {"model": model, "attack": None if cell.clean else cell.attack})
            write_atomic(folder / "episodes.jsonl", "".join(to_json({"episode": i, "return": 0.1 * i + k}) + "\n"
                                                            for i in range(episodes)))
            summary = {"model": model, "episodes": episodes, "mean_return": 21.3 - 0.1 * k,
                       "ci95": [20.0 - k / 3, 22.5],
                       "collision_rate": 0.0 if cell.clean else 0.02 * k, "offroad_rate": 0.0, "mean_speed": 21.9,
                       "right_lane_share": 0.6, "lane_changes_per_episode": 7.37,
                       "attack": None if cell.clean else cell.attack, "defense": None,
                       **({} if cell.clean else {"eps": cell.eps, "attack_success_rate": 0.05 * k,
                                                 "target_base_rate": 0.03, "queries_per_step": 443.4 + k,
                                                 "max_linf": cell.eps})}
            write_json(folder / "summary.json", summary)
            rows.append(table_row(cell.entry(reads), summary))
        write_tables(rows, out, readable=False)
    write_json(row / "row.json", {  # a whole row: the bench reads it through the one row reader (bench/row.py)
        "protocol": "highway-fast-v4", "official": True, "policy": "m", "scenario": "highway-fast", "episodes": 3,
        "clean_episodes": 5, "query_budget": QUERY_CAP, "robustness_area": None, "eps_collisions_pass_brake": None,
        "clean": {"return": 1.0, "collision_rate": 0.0, "ci95": [1.0, 1.0], "speed": 20.0},
        "attacked": [{"eps": e, "return": 1.0, "collision_rate": 0.0, "pgd_return": 1.0} for e in eps]})
    assert len(store.pack_tree(board)) == 3
    return {out / "table.json": (out / "table.json").read_text() for out in grids}


def test_a_packed_bench_grid_gives_its_table_and_pack_removes_it(tmp_path: Path, capsys) -> None:
    """A bench row's table is its packed cells: they give the file's rows exactly (the grid's order, the labels, a
    baseline's ':'), so `zodrive pack` removes the file, and every reader reads the same rows without it."""
    from zodrive.bench.bench import cells_table, read_table

    tables = _bench_grid(tmp_path / "board")
    for path, text in tables.items():
        assert to_json(cells_table(path.parent), indent=2) + "\n" == text
    assert [r["attack"] for r in json.loads(next(iter(tables.values())))][::3] == [
        "none", "random-search", "zo-signsgd", "pgd (white-box)"]  # not the packs' order (by name: pgd second)
    assert main(["pack", str(tmp_path / "board")]) == 0
    out = capsys.readouterr().out
    for path, text in tables.items():
        assert f"removed {path}: its packed cells give it" in out and not path.exists()
        assert read_table(path.parent) == json.loads(text)
    assert main(["pack", str(tmp_path / "board")]) == 0 and "removed" not in capsys.readouterr().out


def test_an_unfinished_bench_grid_keeps_its_table_and_never_reads_as_finished(tmp_path: Path) -> None:
    """A grid that lacks a cell of its row (interrupted between two cells), holds one its row never read (an
    earlier version's, being replaced), or a cell still running keeps its table.json; without the file it is one
    line, never a shorter table."""
    from zodrive.bench.bench import pack_table, read_table

    tables = _bench_grid(tmp_path / "board")
    row = next(iter(tables)).parent
    last = row / "cells" / "m-zo-signsgd-eps0.05-qb500"
    store.remove(last)
    rows = [r for r in json.loads(tables[row / "table.json"]) if not (r["attack"] == "zo-signsgd" and r["eps"] == 0.05)]
    write_json(row / "table.json", rows)  # what compare wrote before it was stopped
    assert "cell m-zo-signsgd-eps0.05-qb500 is missing" in pack_table(row)
    assert json.loads((row / "table.json").read_text()) == rows
    (row / "table.json").unlink()
    with pytest.raises(ZodriveError, match="is not a finished bench grid: cell m-zo-signsgd-eps0.05-qb500 is missing"):
        read_table(row)
    _evaluation(last, 2, finished=False)  # now running again: live, no summary
    write_json(row / "table.json", rows)
    assert "cells not packed" in pack_table(row) and (row / "table.json").is_file()
    (row / "row.json").unlink()  # a forced bench removes its row first: no row.json, no table made of cells
    store.remove(last)
    assert "no row.json" in pack_table(row) and (row / "table.json").is_file()
    other = next(iter(_bench_grid(tmp_path / "other"))).parent
    _evaluation(other / "cells" / "m-random-search-eps0.05", 3)  # a cell of an earlier version, still there
    store.pack(other / "cells")
    assert "cell m-random-search-eps0.05 is not one of its row's" in pack_table(other)
    assert (other / "table.json").is_file()
    fewer = next(iter(_bench_grid(tmp_path / "fewer"))).parent
    row_json = json.loads((fewer / "row.json").read_text())
    write_json(fewer / "row.json", {**row_json, "episodes": 4})  # cells of another episode count than the row's
    assert "m-none holds 3 episodes, its row 4" in pack_table(fewer) and (fewer / "table.json").is_file()


def test_pack_keeps_a_table_its_cells_do_not_give_to_the_bit(tmp_path: Path, capsys) -> None:
    import math

    tables = _bench_grid(tmp_path / "board")
    path = next(iter(tables))
    rows = json.loads(tables[path])
    rows[4]["mean_return"] = math.nextafter(rows[4]["mean_return"], 0.0)  # one ulp
    write_json(path, rows)
    brake = tmp_path / "board" / "highway-fast" / "brake" / "table.json"
    brake_rows = json.loads(tables[brake])
    brake_rows[0]["collision_rate"] = 0  # the same number, an int: not the file the cells give
    write_json(brake, brake_rows)
    assert main(["pack", str(tmp_path / "board")]) == 0
    out = capsys.readouterr().out
    assert f"left {path}: its cells do not give its rows exactly (row 5, mean_return); the file is kept" in out
    assert f"left {brake}: its cells do not give its rows exactly (row 1, collision_rate)" in out
    assert json.loads(path.read_text()) == rows and brake.is_file()
    assert "removed" in out and not (path.parent / "clean" / "table.json").exists()


def test_a_packed_bench_grid_with_a_damaged_pack_is_one_line(tmp_path: Path) -> None:
    from zodrive.bench.bench import read_table

    tables = _bench_grid(tmp_path / "board")
    out = next(iter(tables)).parent
    (out / "table.json").unlink()
    (out / "cells.jsonl.gz").write_bytes(b"not gzip")
    store._lines.cache_clear()
    with pytest.raises(ZodriveError, match=r"^evaluation pack .*cells.jsonl.gz is damaged \(not gzip\)$"):
        read_table(out)
    (out / "cells.jsonl.gz").unlink()
    with pytest.raises(ZodriveError, match="holds no finished comparison"):
        read_table(out)
