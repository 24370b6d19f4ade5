"""A bench row's exact check on the leaderboard: `zodrive certify MODEL --row FOLDER` writes `exact.json`
beside the row, the leaderboard shows its two columns (– without one, or with one of another protocol),
and a malformed file is one line naming it."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from zodrive.bench.leaderboard import leaderboard_markdown, read_rows
from zodrive.cli import main

ROOT = Path(__file__).resolve().parents[1]
ROWS = ROOT / "results" / "bench" / "highway-fast"
DQN = ROOT / "models" / "zoo" / "highway-fast-dqn" / "seed-0"


def _row_folder(board: Path, name: str) -> Path:
    """A board folder holding only the committed row.json of highway-fast row `name` (no cells: the
    leaderboard then has no episodes to pair, and says –)."""
    folder = board / "highway-fast" / name
    folder.mkdir(parents=True)
    shutil.copy(ROWS / name / "row.json", folder / "row.json")
    return folder


def _exact(row: dict, states: int = 100, attackable: tuple[int, ...] = (81, 97, 100),
           unknown: tuple[int, ...] = (2, 0, 0), missed: tuple[int, ...] = (3, 1, 0)) -> dict:
    """An exact.json for `row` (its protocol, key and eps grid) with these counts per eps."""
    points = [{"eps": p["eps"], "robust": states - a - u, "attackable": a, "unknown": u,
               "ensemble": {"found": a - m, "missed": m, "miss_rate": m / a if a else None}}
              for p, a, u, m in zip(row["attacked"], attackable, unknown, missed)]
    return {"protocol": row["protocol"], "key": row["key"], "states": states, "seeds": [100000, 100003],
            "rows": points, "command": "zodrive certify MODEL --row FOLDER --states 100"}


def _line(text: str, policy: str) -> list[str]:
    """The cells of `policy`'s line in the first table that has one."""
    line = next(line for line in text.splitlines() if f"| {policy} |" in line)
    return [cell.strip() for cell in line.strip("|").split("|")]


def test_the_leaderboard_shows_a_rows_exact_check_and_a_dash_without_one(tmp_path: Path) -> None:
    board = tmp_path / "board"
    with_check = _row_folder(board, "dqn-seed-0")
    _row_folder(board, "baseline-rules")
    row = json.loads((with_check / "row.json").read_text())
    (with_check / "exact.json").write_text(json.dumps(_exact(row)))
    text = leaderboard_markdown(read_rows(board))
    header = next(line for line in text.splitlines() if line.startswith("| # | Policy"))
    assert "Exact attackable, ε 0.01 · 0.02 · 0.05 (of clean states)" in header
    assert "Ensemble miss, ε 0.01 · 0.02 · 0.05 (of attackable)" in header
    cells = _line(text, "dqn-seed-0")
    assert len(cells) == len([c for c in header.strip("|").split("|")])  # one cell per column
    assert cells[-2:] == ["81/100 (2 unknown) · 97/100 · 100/100", "3/81 · 1/97 · 0/100"]
    assert _line(text, "baseline-rules")[-2:] == ["–", "–"]
    note = next(line for line in text.splitlines() if line.startswith("- dqn-seed-0:"))
    assert "the first 100 clean states, episodes 100000–100003" in note and "`zodrive certify MODEL" in note


def test_an_exact_check_of_another_protocol_or_model_shows_a_dash_and_says_so(tmp_path: Path) -> None:
    board = tmp_path / "board"
    folder = _row_folder(board, "dqn-seed-0")
    row = json.loads((folder / "row.json").read_text())
    for changed, why in (({"protocol": "highway-fast-v3"}, "of highway-fast-v3, not this table's highway-fast-v4"),
                         ({"key": "sha256:0"}, "of another model file")):
        (folder / "exact.json").write_text(json.dumps({**_exact(row), **changed}))
        text = leaderboard_markdown(read_rows(board))
        assert _line(text, "dqn-seed-0")[-2:] == ["–", "–"]
        note = next(line for line in text.splitlines() if line.startswith("- dqn-seed-0:"))
        assert f"not shown, {why}" in note and "run again `zodrive certify" in note


def test_a_malformed_exact_check_is_one_line_naming_it(tmp_path: Path, capsys) -> None:
    row = json.loads((ROWS / "dqn-seed-0" / "row.json").read_text())
    good = _exact(row)
    bad_rows = [dict(p) for p in good["rows"]]
    bad_rows[0]["attackable"] += 1  # robust + attackable + unknown is no longer the states checked
    lost = [dict(p) for p in good["rows"]]
    lost[1] = {**lost[1], "ensemble": {"found": 0, "missed": 0, "miss_rate": None}}  # found + missed != attackable
    cases = {"not-json": "{", "list": [], "no-rows": {k: v for k, v in good.items() if k != "rows"},
             "empty-rows": {**good, "rows": []}, "rate": {**good, "rows": [{**good["rows"][0], "ensemble": {
                 "found": 1, "missed": 1, "miss_rate": 2.0}}]},
             "sum": {**good, "rows": bad_rows}, "ensemble": {**good, "rows": lost}, "states": {**good, "states": 0}}
    for name, content in cases.items():
        folder = _row_folder(tmp_path / name, "dqn-seed-0")
        (folder / "exact.json").write_text(content if isinstance(content, str) else json.dumps(content))
        assert main(["leaderboard", "--board", str(tmp_path / name), "--out", str(tmp_path / f"{name}.md")]) == 2, name
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "is not an exact check" in err[0] and str(folder / "exact.json") in err[0], (name, err)
    folder = _row_folder(tmp_path / "dir", "dqn-seed-0")
    (folder / "exact.json").mkdir()
    assert main(["leaderboard", "--board", str(tmp_path / "dir"), "--out", str(tmp_path / "dir.md")]) == 2
    assert "not a regular file" in capsys.readouterr().err


def test_certify_row_refuses_in_one_line(tmp_path: Path, capsys) -> None:
    """What the row fixes is refused beside --row; a folder without a row, another model's row and a
    defended row are refused before any episode runs."""
    board = tmp_path / "board"
    folder = _row_folder(board, "dqn-seed-0")
    shield = _row_folder(board, "dqn-seed-0+shield@0.05")
    other = ROOT / "models" / "zoo" / "highway-fast-dqn" / "seed-1"
    for argv in (["--row", str(folder), "--eps", "0.01"], ["--row", str(folder), "--attack", "pgd"],
                 ["--row", str(folder), "--preset", "highway-fast"], ["--row", str(folder), "--episodes", "3"],
                 ["--row", str(tmp_path)], ["--states", "10", "--eps", "0.01"], []):
        assert main(["certify", str(DQN), *argv]) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("zodrive: error:"), (argv, err)
    assert main(["certify", str(other), "--row", str(folder)]) == 2
    assert "is not the policy of" in capsys.readouterr().err
    assert main(["certify", str(DQN), "--row", str(shield)]) == 2
    assert "defended row" in capsys.readouterr().err
    (folder / "exact.json").write_text("{}")
    assert main(["certify", str(DQN), "--row", str(folder)]) == 2
    assert "pass --force" in capsys.readouterr().err
    assert (folder / "exact.json").read_text() == "{}"


def test_certify_row_writes_what_the_leaderboard_reads(tmp_path: Path, monkeypatch, capsys) -> None:
    """On the zoo DQN's own row (states replaced by a few made-up ones: no highway-env episode): the row's
    eps grid, its ensemble at the protocol's query cap, counts that add up, the ensemble missing no more
    than either attack, and the board's cells from the file."""
    import zodrive.evaluation.certify as certify_module

    rng = np.random.default_rng(3)
    x0 = rng.uniform(-0.3, 0.3, (6, 5, 5)).astype(np.float32)
    x0[:, :, 0] = 1.0
    monkeypatch.setattr(certify_module, "first_states", lambda *args: (x0, 1))
    board = tmp_path / "board"
    folder = _row_folder(board, "dqn-seed-0")
    row = json.loads((folder / "row.json").read_text())
    assert main(["certify", str(DQN), "--row", str(folder), "--states", "6", "--time-limit", "5"]) == 0
    assert "black-box ensemble: found" in capsys.readouterr().out
    exact = json.loads((folder / "exact.json").read_text())
    assert (exact["protocol"], exact["key"], exact["states"]) == (row["protocol"], row["key"], len(x0))
    assert exact["black_box"] == ["random-search", "zo-signsgd"] and exact["query_budget"] == row["query_budget"] == 500
    assert [p["eps"] for p in exact["rows"]] == [p["eps"] for p in row["attacked"]]
    assert exact["command"].startswith("zodrive certify") and "--row" in exact["command"]
    for p in exact["rows"]:
        assert p["robust"] + p["attackable"] + p["unknown"] == len(x0) and p["contradictions"] == 0
        e = p["ensemble"]
        assert e["found"] + e["missed"] == p["attackable"]
        assert e["missed"] <= min(a["missed"] for a in p["attacks"].values())
        assert all(a["queries_per_state"] <= 500 for a in p["attacks"].values())  # the protocol's cap
        assert p["per_state"]["exact"].count("a") == p["attackable"]
    cells = _line(leaderboard_markdown(read_rows(board)), "dqn-seed-0")[-2:]
    assert cells[1] == " · ".join(f"{p['ensemble']['missed']}/{p['attackable']}" for p in exact["rows"])
    assert cells[0].startswith(f"{exact['rows'][0]['attackable']}/{len(x0)}")


@pytest.mark.integration
def test_certify_row_on_real_episodes(tmp_path: Path) -> None:
    """The first states of the row's own episodes: as many as asked, from the row's first seed."""
    folder = _row_folder(tmp_path / "board", "dqn-seed-0")
    assert main(["certify", str(DQN), "--row", str(folder), "--states", "8", "--time-limit", "5"]) == 0
    exact = json.loads((folder / "exact.json").read_text())
    assert exact["states"] == 8 and exact["seeds"] == [100000, 100000] and exact["episodes"] == 1
