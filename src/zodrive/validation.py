"""pydantic's checking, said in one line: what every config schema of zodrive (the attack's,
the scenario's, the recipe's) reports when a value is wrong.

A boolean is a boolean (`early_stop: "false"` is refused, not run as true), a number is a number,
ranges are enforced, unknown keys name the closest valid one, and what is recorded is the
validated value.
"""

from __future__ import annotations

import difflib
import reprlib
from typing import Any, Mapping

from pydantic import BaseModel, ConfigDict, ValidationError

Number = float  # strict mode takes ints and floats, never text or booleans


class Strict(BaseModel):
    """A schema that refuses unknown keys and coerces nothing."""

    model_config = ConfigDict(extra="forbid", strict=True)


def one_line(error: ValidationError, context: str, fields: set[str], prefix: str = "") -> str:
    """pydantic's first error as one line, naming the closest valid key for an unknown one."""
    first = error.errors()[0]
    where = prefix + ".".join(str(p) for p in first["loc"])
    if first["type"] == "extra_forbidden":
        close = difflib.get_close_matches(where.split(".")[-1], sorted(fields), n=1)
        return f"unknown key {where!r} in {context}" + (f"; did you mean '{prefix}{close[0]}'?" if close else "")
    value = _short(first.get("input"))
    text = first["msg"].removeprefix("Value error, ")
    for words, sign in (("Input should be greater than or equal to", "must be >="),
                        ("Input should be greater than", "must be >"),
                        ("Input should be less than or equal to", "must be <="),
                        ("Input should be less than", "must be <")):
        text = text.replace(words, sign)
    if first["type"] == "finite_number":
        return f"{context}: {where} must be a finite number, not {value!r}"
    if first["type"] == "too_short":
        least = first.get("ctx", {}).get("min_length", 1)
        return f"{context}: {where} must hold at least {least} item{'' if least == 1 else 's'}, not {value!r}"
    if first["type"] in ("bool_type", "int_type", "float_type", "string_type", "literal_error", "list_type",
                         "dict_type"):
        return f"{context}: {where} must be {_expected(first)}, not {value!r}"
    return f"{context}: {where} {text}" + ("" if repr(value) in text else f" (got {value!r})")


class _short:  # noqa: N801 - a repr cut to one readable line
    def __init__(self, value: Any) -> None:
        self.value = value

    def __repr__(self) -> str:
        text = _REPR.repr(self.value)  # bounded: a huge value is never formatted whole
        return text if len(text) <= 60 else text[:57] + "..."


_REPR = reprlib.Repr()
_REPR.maxstring, _REPR.maxother, _REPR.maxlevel = 80, 80, 3


def _expected(error: Mapping[str, Any]) -> str:
    kind = error["type"]
    if kind == "bool_type":
        return "true or false"
    if kind == "int_type":
        return "an integer"
    if kind in ("float_type", "int_parsing", "float_parsing"):
        return "a number"
    if kind == "string_type":
        return "text"
    if kind == "list_type":
        return "a list"
    if kind == "dict_type":
        return "a mapping"
    return error["msg"].removeprefix("Input should be ").replace("'", "")
