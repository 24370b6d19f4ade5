"""What the leaderboard reads of a bench row's exact check (`exact.json` beside its `row.json`, written
by `zodrive certify MODEL --row FOLDER`, `exact_row`): at each ε of the row's grid, how many of its
sampled clean states are exactly attackable, and how many of those the black-box ensemble missed. A row
without the file, or whose file is of another protocol, model file or ε grid, shows "–"."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from zodrive.errors import ZodriveError

EXACT_FILE = "exact.json"
MAX_EXACT_BYTES = 1 << 20  # a few KiB per 100 states: a larger file is not one
DASH = "–"


class _Gap(BaseModel):
    model_config = ConfigDict(extra="allow")
    found: int = Field(ge=0)
    missed: int = Field(ge=0)
    miss_rate: float | None = Field(ge=0, le=1)


class _Point(BaseModel):
    model_config = ConfigDict(extra="allow")
    eps: float = Field(gt=0)
    robust: int = Field(ge=0)
    attackable: int = Field(ge=0)
    unknown: int = Field(ge=0)
    ensemble: _Gap


class _Exact(BaseModel):
    """What the leaderboard reads of `exact.json`, checked before it reads it."""

    model_config = ConfigDict(extra="allow")
    protocol: str
    key: str
    states: int = Field(ge=1)
    command: str
    rows: list[_Point] = Field(min_length=1)


def read_exact(folder: Path) -> dict[str, Any] | None:
    """The exact check in bench row `folder` (None: it has none), checked for the fields the leaderboard
    reads and for counts that add up; anything else is one line naming the file."""
    path = folder / EXACT_FILE
    if not path.exists():
        return None
    if not path.is_file() or path.stat().st_size > MAX_EXACT_BYTES:
        raise ZodriveError(f"{path} is not an exact check (not a regular file of at most "
                           f"{MAX_EXACT_BYTES >> 20} MiB)")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        checked = _Exact.model_validate(data)
    except (json.JSONDecodeError, UnicodeDecodeError):
        raise ZodriveError(f"{path} is not an exact check (damaged JSON): run its command again") from None
    except ValidationError as exc:
        first = exc.errors()[0]
        raise ZodriveError(f"{path} is not an exact check: {'.'.join(map(str, first['loc']))}: "
                           f"{first['msg']}") from None
    for p in checked.rows:
        if p.robust + p.attackable + p.unknown != checked.states:
            raise ZodriveError(f"{path} is not an exact check: at eps {p.eps:g}, robust + attackable + unknown "
                               f"({p.robust + p.attackable + p.unknown}) is not its {checked.states} states")
        if p.ensemble.found + p.ensemble.missed != p.attackable:
            raise ZodriveError(f"{path} is not an exact check: at eps {p.eps:g}, the ensemble's found + missed "
                               f"({p.ensemble.found + p.ensemble.missed}) is not the {p.attackable} attackable states")
    return dict(data)


def why_not_shown(row: dict[str, Any]) -> str | None:
    """Why the row's exact check (`row["exact"]`, from `read_exact`) is not its own: another protocol,
    model file or ε grid (None: it is, or there is none)."""
    exact = row.get("exact")
    if exact is None:
        return None
    if exact["protocol"] != row["protocol"]:
        return f"of {exact['protocol']}, not this table's {row['protocol']}"
    if exact["key"] != row.get("key"):
        return "of another model file than the row's"
    if [p["eps"] for p in exact["rows"]] != [p["eps"] for p in row["attacked"]]:
        return "of another ε grid than the row's"
    return None


def _shown(row: dict[str, Any]) -> dict[str, Any] | None:
    return None if row.get("exact") is None or why_not_shown(row) else row["exact"]


def exact_headers(eps: list[float]) -> list[str]:
    grid = " · ".join(f"{e:g}" for e in eps)
    return [f"Exact attackable, ε {grid} (of clean states)", f"Ensemble miss, ε {grid} (of attackable)"]


def exact_cells(row: dict[str, Any]) -> list[str]:
    """The row's two exact cells: per ε, attackable of the states checked (and the unknown ones, if
    any), and missed of the attackable ones; "–" without an exact check of its own."""
    exact = _shown(row)
    if exact is None:
        return [DASH, DASH]
    n = exact["states"]
    attackable = " · ".join(f"{p['attackable']}/{n}" + (f" ({p['unknown']} unknown)" if p["unknown"] else "")
                            for p in exact["rows"])
    missed = " · ".join(f"{p['ensemble']['missed']}/{p['attackable']}" for p in exact["rows"])
    return [attackable, missed]


def exact_notes(group: list[dict[str, Any]]) -> list[str]:
    """Under a table: which command made each row's exact columns, and the rows whose exact check is not
    their own (shown as "–", with the command that makes it again)."""
    rows = [r for r in group if r.get("exact") is not None]
    if not rows:
        return []
    lines = ["Exact columns (docs/bench.md, \"The exact check\"): each row's `exact.json`, made by:", ""]
    for r in rows:
        exact, why = r["exact"], why_not_shown(r)
        seeds = exact.get("seeds")
        where = f", episodes {seeds[0]}–{seeds[1]}" if isinstance(seeds, list) and len(seeds) == 2 else ""
        lines.append(f"- {r['policy']}: " + (f"not shown, {why}: run again " if why else
                                             f"the first {exact['states']} clean states{where}: ")
                     + f"`{exact['command']}`")
    return lines + [""]
