"""highway-env's intersection changes the traffic's driver model for the whole process.

`IntersectionEnv._make_vehicles` sets three class attributes of its vehicle type (`IDMVehicle` by
default) on every reset: the jam distance and the comfort accelerations. A highway, merge or
roundabout episode run later in the same process then drives its traffic with intersection's values
and gives other numbers than in a fresh process, silently. `KeepTraffic` gives each environment the
values it was built for: its reset restores highway-env's own (intersection then sets its values
again), and its step refuses when another environment changed them since (two scenarios stepped in
turn in one process), as a wrong number is worse than a refusal. The values restored are those the
classes had when zodrive was imported: a change made to them later, by hand, does not survive a
reset of an environment zodrive built. `zodrive.AttackWrapper` around an environment of your own
does not add the guard: that environment's traffic is yours.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
from highway_env import utils
from highway_env.vehicle.behavior import IDMVehicle

from zodrive.errors import ZodriveError

SHARED = ("DISTANCE_WANTED", "COMFORT_ACC_MAX", "COMFORT_ACC_MIN")
_MISSING = object()


def _family(cls: type[Any]) -> list[type[Any]]:
    return [cls, *(sub for child in cls.__subclasses__() for sub in _family(child))]


#: every IDM class's own value of each shared attribute, as highway-env defines them (taken at import,
#: before any environment of zodrive's runs)
DEFAULTS = {cls: {name: cls.__dict__.get(name, _MISSING) for name in SHARED} for cls in _family(IDMVehicle)}


def restore_defaults() -> None:
    """Put highway-env's own driver-model constants back on every IDM vehicle class."""
    for cls, values in DEFAULTS.items():
        for name, value in values.items():
            if value is _MISSING:
                if name in cls.__dict__:
                    delattr(cls, name)
            else:
                setattr(cls, name, value)


def _values(kind: type) -> tuple[Any, ...]:
    return tuple(getattr(kind, name, None) for name in SHARED)


class KeepTraffic(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """A highway-env environment whose traffic drives with the driver model it was reset with."""

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)
        self._kind = utils.class_from_path(env.unwrapped.config["other_vehicles_type"])  # type: ignore[attr-defined]
        self._values: tuple[Any, ...] | None = None

    def reset(self, **kwargs: Any) -> Any:
        restore_defaults()
        out = self.env.reset(**kwargs)
        self._values = _values(self._kind)
        return out

    def step(self, action: Any) -> Any:
        if self._values is not None and _values(self._kind) != self._values:
            raise ZodriveError("another scenario's environment changed highway-env's driver model for the whole "
                               "process (intersection sets the traffic's IDM constants) since this one's reset: "
                               "step one scenario at a time per process")
        return self.env.step(action)
