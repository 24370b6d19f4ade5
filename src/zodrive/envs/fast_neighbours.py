"""highway-env's neighbour search, exact, projecting each vehicle onto a lane once per decision round.

Every IDM / MOBIL vehicle asks the road for its leader and follower in its own lane, and MOBIL asks
again for each lane it may change to: on highway-fast some 60 questions per simulation step, each
projecting every vehicle of the road onto the lane (`Road.neighbour_vehicles`, a Python loop over
all of them with two `np.dot` per vehicle). While the road's vehicles decide (`Road.act`) nobody
moves, so `FastNeighbourRoad` projects each vehicle onto a lane the first time that lane is asked
about in the round, with highway-env's own `local_coordinates` and `on_lane`, and answers every
question on that lane from those numbers: the same floats, compared in the same order by the same
rules, hence the same leader and follower, ties included. Outside `Road.act` (nothing in highway-env
asks there, but a user's code may) it asks highway-env. Checked against the stock search in
`tests/test_fast_neighbours.py`; measured in `benchmarks/env_speed.py`.
"""

from __future__ import annotations

from typing import Any

from highway_env.road.lane import AbstractLane
from highway_env.road.regulation import RegulatedRoad
from highway_env.road.road import Road
from highway_env.vehicle.objects import Landmark

MARGIN = 1  # [m] highway-env's margin around the lane width in `neighbour_vehicles`

Projection = list  # per entity of the round, in the road's order: its longitudinal coordinate, or None if off the lane


class FastNeighbourRoad(Road):
    """A `Road` whose neighbour search, during `act`, reuses each vehicle's projection onto a lane."""

    _round: dict[int, tuple[AbstractLane, Projection]] | None = None  # id(lane) -> projections, during `act`
    _entities: list[Any] = []

    def act(self) -> None:
        self._entities, self._round = self.vehicles + self.objects, {}
        try:
            super().act()
        finally:
            self._round, self._entities = None, []

    def _projection(self, lane: AbstractLane) -> Projection:
        """Every entity's longitudinal coordinate on `lane`, None where highway-env's test puts it
        off the lane (or where it is a landmark, which the search skips)."""
        assert self._round is not None
        known = self._round.get(id(lane))
        if known is None:
            values: Projection = []
            for v in self._entities:
                if isinstance(v, Landmark):
                    values.append(None)
                    continue
                s_v, lat_v = lane.local_coordinates(v.position)
                values.append(s_v if lane.on_lane(v.position, s_v, lat_v, margin=MARGIN) else None)
            known = self._round[id(lane)] = (lane, values)  # the lane is kept: its id stays its own
        return known[1]

    def neighbour_vehicles(self, vehicle: Any, lane_index: Any = None) -> tuple[Any, Any]:
        if self._round is None:
            return super().neighbour_vehicles(vehicle, lane_index)
        lane_index = lane_index or vehicle.lane_index
        if not lane_index:
            return None, None
        lane = self.network.get_lane(lane_index)
        s = lane.local_coordinates(vehicle.position)[0]
        searched = [(self._projection(lane), 0.0)]
        if self.neighbour_vehicles_connected_lanes:
            searched += [(self._projection(other), offset) for other, offset in _connected(self, lane_index, lane)]
        s_front = s_rear = None
        v_front = v_rear = None
        for i, v in enumerate(self._entities):
            if v is vehicle:
                continue
            for projection, offset in searched:  # the first lane the entity is on, as highway-env searches
                s_v = projection[i]
                if s_v is None:
                    continue
                s_v += offset
                if s <= s_v and (s_front is None or s_v <= s_front):
                    s_front, v_front = s_v, v
                if s_v < s and (s_rear is None or s_v > s_rear):
                    s_rear, v_rear = s_v, v
                break
        return v_front, v_rear


def _connected(road: Road, lane_index: Any, lane: AbstractLane) -> list[tuple[AbstractLane, float]]:
    """The lanes after and before `lane_index` with their offsets, in the order `Road.neighbour_vehicles`
    (highway-env 1.12) searches them."""
    _from, _to, _id = lane_index
    out: list[tuple[AbstractLane, float]] = []
    for next_lanes in road.network.graph.get(_to, {}).values():
        if _id < len(next_lanes):
            out.append((next_lanes[_id], lane.length))
        elif next_lanes:
            out.append((next_lanes[0], lane.length))
    for to_dict in road.network.graph.values():
        if _from in to_dict:
            prev_lanes = to_dict[_from]
            if _id < len(prev_lanes):
                out.append((prev_lanes[_id], -prev_lanes[_id].length))
            elif prev_lanes:
                out.append((prev_lanes[0], -prev_lanes[0].length))
    return out


class FastNeighbourRegulatedRoad(FastNeighbourRoad, RegulatedRoad):
    """The intersection's `RegulatedRoad` (priorities and yielding) with the same neighbour search."""


FAST_ROADS: dict[type, type] = {Road: FastNeighbourRoad, RegulatedRoad: FastNeighbourRegulatedRoad}


def use_fast_neighbours(road: Any) -> None:
    """Make a highway-env `Road` or `RegulatedRoad` (exactly those classes) search neighbours with its fast
    twin (same answers, fewer projections)."""
    fast = FAST_ROADS.get(type(road))
    if fast is not None:
        road.__class__ = fast
