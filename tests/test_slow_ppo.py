"""The shipped PPO (plain stable-baselines3 on highway-fast-v0) reproduces its committed
evaluation, clean and under attack, episode for episode (slow: real highway-env episodes)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from zodrive.cli import main

ROOT = Path(__file__).resolve().parents[1]
CELLS = ROOT / "results" / "ppo-highway-fast" / "cells"


@pytest.mark.slow
@pytest.mark.parametrize("cell,attack", [
    ("ppo-highway-fast-none", []),
    ("ppo-highway-fast-random-search-eps0.05", ["--attack", "random-search", "--eps", "0.05"]),
])
def test_the_shipped_ppo_reproduces_its_committed_cells(tmp_path: Path, cell: str, attack: list[str]) -> None:
    out = tmp_path / cell
    assert main(["evaluate", str(ROOT / "models" / "ppo-highway-fast"), "--preset", "highway-fast", "--episodes", "5",
                 "--out", str(out), "--no-progress", *attack]) == 0
    mine = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    committed = {r["episode"]: r for r in map(json.loads, (CELLS / cell / "episodes.jsonl").read_text().splitlines())}
    for record in mine:
        assert record["return"] == committed[record["episode"]]["return"]
        assert record["crashed"] == committed[record["episode"]]["crashed"]
    if attack:  # the attack hurts: every reproduced episode is at most its clean return
        clean = {r["episode"]: r["return"] for r in map(json.loads, (CELLS / "ppo-highway-fast-none" / "episodes.jsonl")
                                                         .read_text().splitlines())}
        assert sum(r["return"] for r in mine) < sum(clean[r["episode"]] for r in mine)
