"""highway-env scenarios that also know the `FastKinematics` observation type, and search lanes faster.

`zodrive/<id>` is highway-env's `<id>` (same class, same defaults, same simulator) whose
observation factory also accepts `type: FastKinematics`: the exact, pandas-free
`KinematicObservation` of `fast_kinematics`. Its road network answers the closest-lane search of
every vehicle and step with `fast_lanes`, which measures fewer lanes and gives the same lane, and on
highway its road answers the neighbour search of every vehicle with `fast_neighbours`, which projects
fewer vehicles and gives the same leader and follower. Nothing else is swapped.
"""

from __future__ import annotations

from typing import Any

from highway_env.envs.common.abstract import AbstractEnv
from highway_env.envs.highway_env import HighwayEnv, HighwayEnvFast
from highway_env.envs.intersection_env import ConnectedLaneIntersectionEnv
from highway_env.envs.merge_env import ConnectedLaneMergeEnv
from highway_env.envs.racetrack_env import ConnectedLaneRacetrackEnv
from highway_env.envs.roundabout_env import ConnectedLaneRoundaboutEnv

from zodrive.envs.fast_kinematics import FastKinematicObservation
from zodrive.envs.fast_lanes import use_fast_lanes
from zodrive.envs.fast_neighbours import use_fast_neighbours

FAST_TYPE = "FastKinematics"


class FastObservationMixin:
    """Build spaces as highway-env does, then swap a `FastKinematics` observer in."""

    def define_spaces(self) -> None:
        env: AbstractEnv = self
        obs_config = env.config["observation"]
        if obs_config.get("type") != FAST_TYPE:
            super().define_spaces()  # type: ignore[misc]
            return
        env.config["observation"] = {**obs_config, "type": "Kinematics"}
        try:
            super().define_spaces()  # type: ignore[misc]
        finally:
            env.config["observation"] = obs_config
        kwargs = {k: v for k, v in obs_config.items() if k != "type"}
        env.observation_type = FastKinematicObservation(env, **kwargs)
        env.observation_space = env.observation_type.space()


class FastLanesMixin:
    """Build the road as highway-env does (`_create_road` on highway, `_make_road` elsewhere), then let
    its network search lanes with `FastLaneNetwork`, before any vehicle is placed; on highway (many
    vehicles on few lanes: each lane is asked about dozens of times a round) the road also searches
    neighbours with `FastNeighbourRoad`. Elsewhere it was no faster (`benchmarks/lane_search.py
    --search neighbours`), so highway-env's search stays."""

    def _create_road(self, *args: Any, **kwargs: Any) -> None:
        super()._create_road(*args, **kwargs)  # type: ignore[misc]
        use_fast_lanes(self.road.network)  # type: ignore[attr-defined]
        use_fast_neighbours(self.road)  # type: ignore[attr-defined]

    def _make_road(self, *args: Any, **kwargs: Any) -> None:
        super()._make_road(*args, **kwargs)  # type: ignore[misc]
        use_fast_lanes(self.road.network)  # type: ignore[attr-defined]


class ZodriveHighwayEnv(FastObservationMixin, FastLanesMixin, HighwayEnv):
    """`highway-v0` with `observation.type: FastKinematics` available."""


class ZodriveHighwayFastEnv(FastObservationMixin, FastLanesMixin, HighwayEnvFast):
    """`highway-fast-v0` (3 lanes, 5 Hz simulation, 1 decision per second)."""


class ZodriveMergeEnv(FastObservationMixin, FastLanesMixin, ConnectedLaneMergeEnv):
    """`merge-v1`: join the highway from an on-ramp."""


class ZodriveRoundaboutEnv(FastObservationMixin, FastLanesMixin, ConnectedLaneRoundaboutEnv):
    """`roundabout-v1`: enter and leave a roundabout."""


class ZodriveIntersectionEnv(FastObservationMixin, FastLanesMixin, ConnectedLaneIntersectionEnv):
    """`intersection-v2`: cross an unsignalized intersection (speed actions only)."""


class ZodriveRacetrackEnv(FastObservationMixin, FastLanesMixin, ConnectedLaneRacetrackEnv):
    """`racetrack-v1`: follow a closed track by steering."""


FAST_ENVS = {  # zodrive id -> (class name in this module, highway-env id it extends)
    "zodrive/highway-v0": ("ZodriveHighwayEnv", "highway-v0"),
    "zodrive/highway-fast-v0": ("ZodriveHighwayFastEnv", "highway-fast-v0"),
    "zodrive/merge-v1": ("ZodriveMergeEnv", "merge-v1"),
    "zodrive/roundabout-v1": ("ZodriveRoundaboutEnv", "roundabout-v1"),
    "zodrive/intersection-v2": ("ZodriveIntersectionEnv", "intersection-v2"),
    "zodrive/racetrack-v1": ("ZodriveRacetrackEnv", "racetrack-v1"),
}
