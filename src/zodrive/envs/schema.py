"""A preset's `highway:` mapping, typed from the scenario's own default config (a key whose
default is an integer takes integers, and so on), with the ranges that keep highway-env from
silently doing nonsense (a negative or infinite duration, a zero frequency, an empty feature
list, a feature range it divides by zero with)."""

from __future__ import annotations

import functools
import math
from typing import Annotated, Any, Literal, Optional, Union

from pydantic import BaseModel, ConfigDict, Field, StrictBool, StrictInt, ValidationError, create_model

from zodrive.errors import ZodriveError
from zodrive.validation import Number, one_line

Finite = Annotated[Number, Field(allow_inf_nan=False)]  # highway-env multiplies and divides by these


RANGES: dict[str, dict[str, float]] = {  # keys highway-env accepts nonsense for
    "duration": {"gt": 0}, "vehicles_count": {"ge": 0}, "controlled_vehicles": {"ge": 1}, "lanes_count": {"ge": 1},
    "simulation_frequency": {"ge": 1}, "policy_frequency": {"ge": 1}, "initial_lane_id": {"ge": 0},
    "ego_spacing": {"gt": 0}, "vehicles_density": {"gt": 0}, "screen_width": {"ge": 1}, "screen_height": {"ge": 1},
    "scaling": {"gt": 0}, "initial_vehicle_count": {"ge": 0}, "spawn_probability": {"ge": 0, "le": 1},
}
OBSERVATION_FIELDS: dict[str, Any] = {
    "type": (Optional[str], None), "vehicles_count": (StrictInt, Field(None, ge=1)),
    "features": (list[str], Field(None, min_length=1)), "features_range": (Optional[dict[str, list[Finite]]], None),
    "absolute": (StrictBool, None),
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
        return StrictInt if key in INTEGER_KEYS else Finite
    if isinstance(default, float):
        return Finite
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
        rules: dict[str, Any] = RANGES.get(key, {})
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
        raise ZodriveError(one_line(exc, context, set(defaults), "highway.")) from None
    observation = config.get("observation")
    if isinstance(observation, dict):
        try:
            _OBSERVATION.model_validate(observation)
        except ValidationError as exc:
            raise ZodriveError(one_line(exc, context, set(OBSERVATION_FIELDS), "highway.observation.")) from None
        _check_observer_keys(observation, defaults.get("observation") or {}, context)
        features = observation.get("features") or []
        twice = sorted({f for f in features if features.count(f) > 1})
        if twice:
            raise ZodriveError(f"{context}: highway.observation.features names {twice[0]!r} twice")
        for name, bounds in (observation.get("features_range") or {}).items():
            _check_range(bounds, f"highway.observation.features_range.{name}", context, strict=True)
    if "reward_speed_range" in config:
        _check_range(config["reward_speed_range"], "highway.reward_speed_range", context, strict=True)
    action = config.get("action")
    if isinstance(action, dict):
        for key in ("acceleration_range", "steering_range", "speed_range"):
            if key in action:
                _check_range(action[key], f"highway.action.{key}", context, strict=False)


@functools.cache
def observer_options(kind: str) -> frozenset[str] | None:
    """The options highway-env's observer `kind` reads: its constructors' parameters (None: a type zodrive
    does not know, which `validate_preset` refuses)."""
    import inspect

    from highway_env.envs.common import observation as hw

    from zodrive.envs.fast_kinematics import FastKinematicObservation

    cls = {"Kinematics": hw.KinematicObservation, "FastKinematics": FastKinematicObservation,
           "ExitObservation": hw.ExitObservation, "OccupancyGrid": hw.OccupancyGridObservation,
           "GrayscaleObservation": hw.GrayscaleObservation, "TimeToCollision": hw.TimeToCollisionObservation,
           "LidarObservation": hw.LidarObservation}.get(kind)
    if cls is None:
        return None
    return frozenset(p.name for c in cls.__mro__ if "__init__" in c.__dict__
                     for p in inspect.signature(c.__init__).parameters.values()
                     if p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL) and p.name not in ("self", "env"))


def _check_observer_keys(observation: dict[str, Any], default: dict[str, Any], context: str) -> None:
    """highway-env's observers take **kwargs and drop what they do not read: a key the observer ignores (a typo,
    a Kinematics option left beside `type: GrayscaleObservation`) would run silently, so it is an error. Keys of
    the scenario's own default observation are allowed (intersection's defaults carry `flatten`)."""
    kind = observation.get("type", default.get("type", "Kinematics"))
    reads = observer_options(kind)
    if reads is None:
        return
    kinematics = {"Kinematics", "FastKinematics", "ExitObservation"}  # one observer, three implementations
    same = kind == default.get("type", "Kinematics") or {kind, default.get("type", "Kinematics")} <= kinematics
    ignored = sorted(k for k in observation if k != "type" and k not in reads and not (same and k in default))
    if ignored:
        raise ZodriveError(f"{context}: highway.observation.{ignored[0]} is not an option of {kind}, "
                           f"which would ignore it (it reads {', '.join(sorted(reads))}); to change the "
                           "observation type, give the whole mapping in a preset file")


def _check_range(value: Any, where: str, context: str, strict: bool) -> None:
    """[low, high]: two finite numbers, low < high (`strict`: highway-env divides by high - low)
    or low <= high."""
    numbers = isinstance(value, list) and len(value) == 2 and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    if not numbers or (value[0] >= value[1] if strict else value[0] > value[1]):
        shape = "low < high" if strict else "low <= high"
        raise ZodriveError(f"{context}: {where} must be [low, high], two finite numbers with {shape}, "
                           f"not {str(value)[:60]}")
