"""Run a grid of evaluation cells: in this process (default) or as Ray tasks.

Every cell is an ordinary resumable evaluation writing to its own folder, so the backend
only decides where cells run; what scales is the number of cells, not the steps inside one.
`backend="ray"` starts a local Ray instance with `workers` CPUs, or joins the cluster at
`address`; every worker must see the same output folder (a shared file system on a cluster).
A cell whose folder was packed (`zodrive pack`, `evaluation.store`) is finished where its line holds this
evaluation's key and episodes: nothing runs; otherwise its folder is given back first and the evaluation
resumes, or refuses, as it would from the folder.

A cell of a grid is named by a `GridCell` (the policy's name in the grid, the attack, eps, query budget and
defense): its folder and its table label are made there and nowhere else, and read back from a table's entry
there (`GridCell.from_entry`), so that a bench or a leaderboard never rebuilds a folder name or parses a label.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator

from zodrive.errors import ZodriveError
from zodrive.evaluation import store
from zodrive.evaluation.evaluate import DEFAULT_ENVS, EvalJob, evaluate, same_evaluation

BACKENDS = ("local", "ray")


def number_name(value: float) -> str:
    """A number in a cell folder's name: the short form (`0.05`, `1e-05`) where it names the
    value exactly, which every committed cell's does, else the float's shortest exact repr
    (`0.1000001`): two different numbers never share a cell."""
    short = f"{value:g}"
    return short if float(short) == float(value) else repr(float(value))


def policy_names(labels: list[str], keys: list[str]) -> list[str]:
    """Each policy's name in cell folders and tables: its label, and where two different
    policies share one (two files named model.zip) a short digest of its content key after it."""
    names = []
    for label, key in zip(labels, keys):
        clash = any(other == label and other_key != key for other, other_key in zip(labels, keys))
        names.append(f"{label}-{hashlib.sha256(key.encode()).hexdigest()[:8]}" if clash else label)
    return names


CLEAN = "none"
"""The attack of a grid's clean cell (no perturbation)."""
WHITE_BOX_MARK = " (white-box)"
"""What a table's label adds to a white-box attack's name (`pgd (white-box)`)."""


@dataclass(frozen=True)
class GridCell:
    """One cell of a grid, by what it evaluates: the one place its folder name and its table label are made."""

    model: str
    """The policy's name in the grid (`policy_names`: its label, a digest after it where two share one)."""
    attack: str = CLEAN
    """The attack as the grid names it (`compare.attack_name`: registry name, config stem or NAME:DIR)."""
    eps: float | None = None
    query_budget: int | None = None
    defense: str | None = None
    """What stands between the sensor and the policy (None: nothing)."""
    white_box: bool = False
    """Whether the attack reads gradients: its label says so."""

    @property
    def clean(self) -> bool:
        return self.attack == CLEAN

    @property
    def name(self) -> str:
        """The cell's folder name: MODEL[+DEFENSE]-ATTACK[-epsEPS][-qbBUDGET], ':' as '-'."""
        return (self.model.replace(":", "-") + ("" if self.defense is None else f"+{self.defense}")
                + f"-{self.attack.replace(':', '-')}" + ("" if self.eps is None else f"-eps{number_name(self.eps)}")
                + ("" if self.query_budget is None else f"-qb{self.query_budget}"))

    def folder(self, out: Path) -> Path:
        """The cell's folder in the grid of folder `out`."""
        return out / "cells" / self.name

    @property
    def label(self) -> str:
        """The attack as a table shows it (white-box ones say so)."""
        return self.attack + (WHITE_BOX_MARK if self.white_box else "")

    def entry(self, reads: str) -> dict[str, Any]:
        """The cell's entry in `grid.json` (and the first fields of its `table.json` row)."""
        return {"model": self.model, "defense": self.defense or "none", "reads": reads, "attack": self.label,
                "eps": self.eps, "query_budget": self.query_budget}

    @classmethod
    def from_entry(cls, entry: dict[str, Any]) -> GridCell:
        """The cell of a `grid.json` or `table.json` entry (`entry` backwards)."""
        label = str(entry["attack"])
        defense = entry.get("defense")
        return cls(model=entry["model"], attack=label.removesuffix(WHITE_BOX_MARK), eps=entry["eps"],
                   query_budget=entry.get("query_budget"), defense=None if defense in (None, "none") else defense,
                   white_box=label.endswith(WHITE_BOX_MARK))


def clean_cells(out: Path) -> list[Path]:
    """The folders (or packed cells) of the clean cells in the grid of folder `out`, whatever its policies."""
    return store.names(out / "cells", f"*-{CLEAN}")


@dataclass
class Cell:
    job: EvalJob
    episodes: int
    folder: Path
    force: bool = False  # replace another evaluation in `folder` (evaluate's output rule)


def _run_one(cell: Cell, envs: int) -> dict[str, Any]:
    return evaluate(cell.job, cell.episodes, cell.folder, workers=1, envs=envs, progress=False, force=cell.force)


def run_cells(cells: list[Cell], *, backend: str = "local", workers: int = 1, progress: bool = True,
              address: str | None = None, on_done: Callable[[int, dict[str, Any]], None] | None = None,
              envs: int = DEFAULT_ENVS) -> list[dict[str, Any]]:
    """The summaries of `cells`, in order; `on_done(i, summary)` as each one finishes. Each
    cell runs `envs` episodes side by side per process."""
    if backend not in BACKENDS:
        raise ZodriveError(f"unknown backend {backend!r} (known: {', '.join(BACKENDS)})")
    results: list[dict[str, Any] | None] = [None] * len(cells)
    todo = []
    for i, cell in enumerate(cells):
        summary = packed_summary(cell)
        if summary is None:
            todo.append(i)
            continue
        results[i] = summary
        if on_done is not None:
            on_done(i, summary)
    runs = [cells[i] for i in todo]
    stream = _local(runs, workers, progress, envs, [f"cell {i + 1}/{len(cells)}" for i in todo]) \
        if backend == "local" else _ray(runs, workers, address, envs)
    for j, summary in stream:
        results[todo[j]] = summary
        if on_done is not None:
            on_done(todo[j], summary)
    return results  # type: ignore[return-value]


def packed_summary(cell: Cell) -> dict[str, Any] | None:
    """The summary of a packed cell that holds this evaluation finished (the same key, exactly the episodes
    asked for), as `evaluate` returns a finished folder's; None otherwise, after giving a packed cell its
    folder back, so that the evaluation resumes (or refuses) from it as from any folder."""
    if store.is_live(cell.folder) or not store.exists(cell.folder):
        return None
    found = store.read(cell.folder)
    wanted = json.loads(json.dumps(cell.job.key()))
    if found.key is not None and found.summary is not None and same_evaluation(found.key, wanted) \
            and found.summary.get("episodes") == cell.episodes \
            and {r.get("episode") for r in found.episodes} >= set(range(cell.episodes)):
        return found.summary
    store.unpack(cell.folder)
    return None


def _local(cells: list[Cell], workers: int, progress: bool, envs: int,
           numbers: list[str]) -> Iterator[tuple[int, dict[str, Any]]]:
    for i, (cell, number) in enumerate(zip(cells, numbers)):  # one cell at a time, its episodes over `workers`
        yield i, evaluate(cell.job, cell.episodes, cell.folder, workers=workers, envs=envs, progress=progress,
                          force=cell.force, label=f"{number} {cell.folder.name}")


def _ray(cells: list[Cell], workers: int, address: str | None, envs: int) -> Iterator[tuple[int, dict[str, Any]]]:
    try:
        import ray
    except ImportError:
        raise ZodriveError("--backend ray needs Ray: pip install 'zodrive[ray]'") from None
    if not ray.is_initialized():
        try:
            if address:
                ray.init(address=address, log_to_driver=False)
            else:
                ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
        except (ConnectionError, RuntimeError, ValueError, OSError, TimeoutError) as exc:
            from zodrive.errors import cause

            where = f"the Ray cluster at {address}" if address else "a local Ray instance"
            raise ZodriveError(f"--backend ray: {where} did not start: {cause(exc)}") from None
    task = ray.remote(num_cpus=1)(_run_one)
    pending = {task.remote(cell, envs): i for i, cell in enumerate(cells)}
    while pending:
        done, _ = ray.wait(list(pending), num_returns=1)
        for ref in done:
            yield pending.pop(ref), ray.get(ref)
