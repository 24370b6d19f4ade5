"""The attack's options: their types and ranges (`AttackSpec.from_mapping` validates through it)."""

from __future__ import annotations

import math
from typing import Any, Literal, Optional, Union

from pydantic import Field, StrictBool, StrictInt, ValidationError, field_validator

from zodrive.errors import ZodriveError
from zodrive.validation import Strict, one_line


class AttackOptions(Strict):
    """The options of an attack (`AttackSpec`): types and ranges."""

    attack: str = "zo-signsgd"
    eps: float = Field(0.2, gt=0)
    norm: Literal["linf", "l2"] = "linf"
    mode: Literal["budgeted", "paper"] = "budgeted"
    frozen: tuple[str, ...] = ("presence",)
    steps: StrictInt = Field(100, ge=1)
    n_directions: StrictInt = Field(20, ge=1)
    mu: float = Field(0.005, gt=0)
    step_size: float = Field(0.02, gt=0)
    l2_weight: float = Field(0.0, ge=0)
    target: Union[str, StrictInt, list[float]] = "auto"
    loss: Literal["margin", "paper"] = "margin"
    weight: float = Field(1.0, gt=0)
    kappa: float = Field(0.01, ge=0)
    tol: float = Field(0.2, gt=0)
    early_stop: StrictBool = True
    patience: Optional[StrictInt] = Field(None, ge=1)
    warm_start: StrictBool = False
    on_failure: Literal["best", "clean"] = "best"
    restarts: StrictInt = Field(0, ge=0)
    timing: Optional[float] = Field(None, ge=0, le=1)
    episode_query_budget: Optional[StrictInt] = Field(None, ge=1)
    max_change: Optional[float] = Field(None, gt=0)
    access: Literal["score", "decision"] = "score"
    query_budget: Optional[StrictInt] = Field(None, ge=1)
    seed: StrictInt = Field(0, ge=0)
    adversary: Optional[str] = None
    check_below: Optional[float] = Field(None, ge=0, le=1)

    @field_validator("eps", "mu", "step_size", "l2_weight", "weight", "kappa", "tol", "timing", "max_change",
                     "check_below", mode="before")
    @classmethod
    def _finite_number(cls, value: Any) -> Any:
        if isinstance(value, bool) or (value is not None and not isinstance(value, (int, float))):
            raise ValueError(f"must be a number, not {value!r}")
        if value is not None and not math.isfinite(value):
            raise ValueError(f"must be a finite number, not {value}")
        return float(value) if value is not None else None

    @field_validator("frozen", mode="before")
    @classmethod
    def _names(cls, value: Any) -> Any:
        if value is None:
            return ()
        if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
            raise ValueError(f"must be a list of feature names, not {value!r}")
        return tuple(value)

    @field_validator("target", mode="before")
    @classmethod
    def _target(cls, value: Any) -> Any:
        if isinstance(value, tuple):
            value = list(value)
        if isinstance(value, list) and not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
            raise ValueError(f"a continuous target is a list of numbers, not {value!r}")
        if isinstance(value, list):
            return [float(v) for v in value]
        if isinstance(value, bool) or value is None:
            raise ValueError(f"must be auto, none, worst, an action name or index, or a list, not {value!r}")
        return value


def validate_attack(data: dict[str, Any], context: str = "attack config") -> dict[str, Any]:
    """The validated attack options (unknown keys, wrong types and ranges are one-line errors)."""
    try:
        return AttackOptions.model_validate(data).model_dump()
    except ValidationError as exc:
        raise ZodriveError(one_line(exc, context, set(AttackOptions.model_fields))) from None
