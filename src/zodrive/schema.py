"""One typed schema for every config a user writes: attack YAML and `--attack-set`, preset
overrides (`--set`, `--env-set`) and training recipes.

pydantic does the checking: a boolean is a boolean (`early_stop: "false"` is refused, not run
as true), a number is a number, ranges are enforced, unknown keys name the closest valid one,
and what is recorded is the validated value. highway-env's keys are typed from the scenario's
own default config (a key whose default is an integer takes integers, and so on), with the
ranges that keep highway-env from silently doing nonsense (a negative duration, a zero
frequency).
"""

from __future__ import annotations

import difflib
import math
from typing import Any, Literal, Optional, Union

from pydantic import BaseModel, ConfigDict, Field, StrictBool, StrictInt, ValidationError, create_model, field_validator

from zodrive.errors import ZodriveError

Number = float  # strict mode takes ints and floats, never text or booleans


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)


class AttackOptions(_Strict):
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


def _message(error: ValidationError, context: str, fields: set[str], prefix: str = "") -> str:
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
                        ("Input should be less than or equal to", "must be <="), ("Input should be less than", "must be <")):
        text = text.replace(words, sign)
    if first["type"] in ("bool_type", "int_type", "float_type", "string_type", "literal_error", "list_type",
                         "dict_type"):
        return f"{context}: {where} must be {_expected(first)}, not {value!r}"
    return f"{context}: {where} {text}" + ("" if repr(value) in text else f" (got {value!r})")


class _short:  # noqa: N801 - a repr cut to one readable line
    def __init__(self, value: Any) -> None:
        self.value = value

    def __repr__(self) -> str:
        text = repr(self.value)
        return text if len(text) <= 60 else text[:57] + "..."


def _expected(error: dict[str, Any]) -> str:
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


def validate_attack(data: dict[str, Any], context: str = "attack config") -> dict[str, Any]:
    """The validated attack options (unknown keys, wrong types and ranges are one-line errors)."""
    try:
        return AttackOptions.model_validate(data).model_dump()
    except ValidationError as exc:
        raise ZodriveError(_message(exc, context, set(AttackOptions.model_fields))) from None


# ---------------------------------------------------------------- highway-env configs

RANGES: dict[str, dict[str, float]] = {  # keys highway-env accepts nonsense for
    "duration": {"gt": 0}, "vehicles_count": {"ge": 0}, "controlled_vehicles": {"ge": 1}, "lanes_count": {"ge": 1},
    "simulation_frequency": {"ge": 1}, "policy_frequency": {"ge": 1}, "initial_lane_id": {"ge": 0},
    "ego_spacing": {"gt": 0}, "vehicles_density": {"gt": 0}, "screen_width": {"ge": 1}, "screen_height": {"ge": 1},
    "scaling": {"gt": 0}, "initial_vehicle_count": {"ge": 0}, "spawn_probability": {"ge": 0, "le": 1},
}
OBSERVATION_FIELDS: dict[str, Any] = {
    "type": (Optional[str], None), "vehicles_count": (StrictInt, Field(None, ge=1)), "features": (list[str], None),
    "features_range": (Optional[dict[str, list[float]]], None), "absolute": (StrictBool, None),
    "normalize": (StrictBool, None), "clip": (StrictBool, None), "see_behind": (StrictBool, None),
    "observe_intentions": (StrictBool, None), "order": (Literal["sorted", "shuffled"], None),
    "flatten": (StrictBool, None), "include_obstacles": (StrictBool, None),
}


INTEGER_KEYS = {"vehicles_count", "controlled_vehicles", "lanes_count", "simulation_frequency", "policy_frequency",
                "initial_lane_id", "screen_width", "screen_height", "initial_vehicle_count", "other_vehicles"}


def _field_type(key: str, default: Any) -> Any:
    """The type a highway-env key takes, from its default value (counts stay integers; other
    integer defaults such as rewards take any number)."""
    if isinstance(default, bool):
        return StrictBool
    if isinstance(default, int):
        return StrictInt if key in INTEGER_KEYS else Number
    if isinstance(default, float):
        return Number
    if isinstance(default, str):
        return Union[str, None]
    if isinstance(default, (list, tuple)):
        return list
    if isinstance(default, dict):
        return dict
    return Any


def _highway_model(defaults: dict[str, Any]) -> type[BaseModel]:
    fields: dict[str, Any] = {}
    for key, default in defaults.items():
        kind = _field_type(key, default)
        rules = RANGES.get(key, {})
        fields[key] = (Optional[kind] if default is None or kind is Any else kind, Field(None, **rules))
    fields["observation"] = (dict, None)
    return create_model("HighwayConfig", __config__=ConfigDict(extra="forbid", strict=True), **fields)


_OBSERVATION = create_model("ObservationConfig", __config__=ConfigDict(extra="allow", strict=True),
                            **OBSERVATION_FIELDS)


def validate_highway(config: dict[str, Any], defaults: dict[str, Any], context: str) -> None:
    """Check a preset's `highway:` mapping against the scenario's default config: types from
    the defaults, ranges from `RANGES`, the Kinematics options typed (`OBSERVATION_FIELDS`)."""
    try:
        _highway_model(defaults).model_validate(config)
    except ValidationError as exc:
        raise ZodriveError(_message(exc, context, set(defaults), "highway.")) from None
    observation = config.get("observation")
    if isinstance(observation, dict):
        try:
            _OBSERVATION.model_validate(observation)
        except ValidationError as exc:
            raise ZodriveError(_message(exc, context, set(OBSERVATION_FIELDS), "highway.observation.")) from None


# ---------------------------------------------------------------- recipes

POSITIVE_INTS = ("batch_size", "buffer_size", "gradient_steps", "target_update_interval", "n_steps", "n_epochs",
                 "policy_delay")
NON_NEGATIVE_INTS = ("learning_starts",)
UNIT = ("gamma", "tau", "exploration_fraction", "exploration_initial_eps", "exploration_final_eps", "gae_lambda")


def validate_hyperparameters(params: dict[str, Any], context: str) -> None:
    """Types and ranges of the SB3 hyperparameters a recipe sets (`--set hyperparameters.K=V`)."""
    for key, value in params.items():
        where = f"{context}: hyperparameters.{key}"
        if key in POSITIVE_INTS + NON_NEGATIVE_INTS:
            least = 0 if key in NON_NEGATIVE_INTS else 1
            if isinstance(value, bool) or not isinstance(value, int) or value < least:
                raise ZodriveError(f"{where} must be an integer >= {least}, not {value!r}")
        elif key in UNIT or key == "learning_rate":
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ZodriveError(f"{where} must be a number, not {value!r}")
            if key == "learning_rate" and value <= 0:
                raise ZodriveError(f"{where} must be > 0, not {value!r}")
            if key in UNIT and not 0 <= value <= 1:
                raise ZodriveError(f"{where} must be in [0, 1], not {value!r}")
        elif key == "train_freq" and not (isinstance(value, int) and not isinstance(value, bool) and value >= 1
                                          or isinstance(value, list)):
            raise ZodriveError(f"{where} must be an integer >= 1 (or [N, step|episode]), not {value!r}")
