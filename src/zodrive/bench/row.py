"""A bench row's file, `row.json`: its name's pattern, its key (`row_key`, read back by `key_parts`), the fields
its readers need, and the one reader that checks them (the bench resuming or packing a row, the leaderboard, the
exact columns, the zoo's cards): rows come from strangers too, so a file that is not one is one line naming it,
never a traceback."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from zodrive.defense import defense_version
from zodrive.errors import ZodriveError

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
    """What the bench and the leaderboard read of a row, checked before they read it (rows come from strangers too)."""

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
        _Row.model_validate(row, strict=True)  # strict: the dict returned holds the types checked
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


DEFENSE_KEY = "+defense:"
"""What joins a row's policy key and its defense (`row_key`)."""


def row_key(policy_key: str, defense: str | None) -> str:
    """A row's key: the policy's content key, and the defense with the version of its behaviour
    (`POLICY+defense:NAME:vN`; no version for an unversioned defense)."""
    if defense is None:
        return policy_key
    version = defense_version(defense)
    return f"{policy_key}{DEFENSE_KEY}{defense}" + (f":v{version}" if version is not None else "")


def key_parts(key: str) -> tuple[str, int | None]:
    """`row_key` read back: the policy's key and the defense version the row ran (None: undefended or
    unversioned)."""
    policy, joined, defense = key.partition(DEFENSE_KEY)
    _, marked, version = defense.rpartition(":v")
    return policy, int(version) if joined and marked and version.isdigit() else None
