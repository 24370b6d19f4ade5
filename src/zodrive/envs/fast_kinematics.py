"""A pandas-free `KinematicObservation` that returns exactly highway-env's array.

highway-env builds two pandas DataFrames per step to observe five vehicles, which costs
about half of an environment step. This class keeps highway-env's vehicle selection
(`Road.close_objects_to`) and replaces only the table work with numpy, doing the same
float64 arithmetic in the same order, so the result is bit-identical (checked in
`tests/test_fast_kinematics.py` against the stock class on thousands of states).
"""

from __future__ import annotations

import numpy as np
from highway_env import utils
from highway_env.envs.common.observation import KinematicObservation
from highway_env.road.lane import AbstractLane
from highway_env.vehicle.kinematics import Vehicle

_RELATIVE = ("x", "y", "vx", "vy")


def _feature(vehicle: Vehicle, name: str, observe_intentions: bool) -> float:
    """One entry of `Vehicle.to_dict()` without building the whole dict."""
    if name == "presence":
        return 1.0
    if name == "x":
        return vehicle.position[0]
    if name == "y":
        return vehicle.position[1]
    if name == "vx":
        return vehicle.velocity[0]
    if name == "vy":
        return vehicle.velocity[1]
    if name == "heading":
        return vehicle.heading
    if name == "cos_h":
        return vehicle.direction[0]
    if name == "sin_h":
        return vehicle.direction[1]
    if name in ("cos_d", "sin_d"):
        if not observe_intentions:
            return 0.0
        return vehicle.destination_direction[0 if name == "cos_d" else 1]
    if name in ("long_off", "lat_off", "ang_off"):
        return vehicle.lane_offset[("long_off", "lat_off", "ang_off").index(name)]
    raise KeyError(name)


class FastKinematicObservation(KinematicObservation):
    """Drop-in replacement for highway-env's `Kinematics` observation type."""

    features_range: dict[str, list[float]] | None  # set by the base class; filled in by `_normalize`

    def _rows(self, vehicles: list, origin: Vehicle | None, intentions: bool) -> np.ndarray:
        rows = np.array(
            [[_feature(v, f, intentions) for f in self.features] for v in vehicles],
            dtype=np.float64,
        )
        if origin is not None:
            for j, name in enumerate(self.features):
                if name in _RELATIVE:
                    rows[:, j] -= _feature(origin, name, True)
        return rows

    def _normalize(self, obs: np.ndarray) -> None:
        if not self.features_range:
            side_lanes = self.env.road.network.all_side_lanes(self.observer_vehicle.lane_index)
            self.features_range = {
                "x": [-5.0 * Vehicle.MAX_SPEED, 5.0 * Vehicle.MAX_SPEED],
                "y": [
                    -AbstractLane.DEFAULT_WIDTH * len(side_lanes),
                    AbstractLane.DEFAULT_WIDTH * len(side_lanes),
                ],
                "vx": [-2 * Vehicle.MAX_SPEED, 2 * Vehicle.MAX_SPEED],
                "vy": [-2 * Vehicle.MAX_SPEED, 2 * Vehicle.MAX_SPEED],
            }
        for feature, f_range in self.features_range.items():
            if feature in self.features:
                j = self.features.index(feature)
                obs[:, j] = utils.lmap(obs[:, j], [f_range[0], f_range[1]], [-1, 1])
                if self.clip:
                    obs[:, j] = np.clip(obs[:, j], -1, 1)

    def observe(self) -> np.ndarray:
        if not self.env.road:
            return np.zeros(self.space().shape)
        ego = self.observer_vehicle
        obs = self._rows([ego], None, True)
        close = self.env.road.close_objects_to(
            ego,
            self.env.PERCEPTION_DISTANCE,
            count=self.vehicles_count - 1,
            see_behind=self.see_behind,
            sort=self.order == "sorted",
            vehicles_only=not self.include_obstacles,
        )
        if close:
            origin = ego if not self.absolute else None
            others = close[-self.vehicles_count + 1 :]
            obs = np.vstack([obs, self._rows(others, origin, self.observe_intentions)])
        if self.normalize:
            self._normalize(obs)
        if obs.shape[0] < self.vehicles_count:
            pad = np.zeros((self.vehicles_count - obs.shape[0], len(self.features)))
            obs = np.vstack([obs, pad])
        if self.order == "shuffled":
            self.env.np_random.shuffle(obs[1:])
        return obs.astype(self.space().dtype)
