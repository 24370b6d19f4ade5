"""highway-env's closest-lane search, exact and without measuring every lane.

Every vehicle asks the road network for its closest lane at every simulation step, and
`RoadNetwork.get_closest_lane_index` measures its weighted distance to every lane of the map: a third
of an intersection step and over half of a roundabout step. `FastLaneNetwork` gives the same answer
while measuring only the lanes that can win. Each lane has a lower bound on its distance (the distance
to a box around its centre line, less a sine lane's amplitude); lanes are measured by highway-env's
own `distance_with_heading`, nearest box first, until the next bound exceeds the best distance found.
A lane left unmeasured is farther than the best by more than float rounding, so it could neither win
nor tie, and ties go to the first lane in the network's order, as `np.argmin` gives them. Lane types
without a bound here are always measured. Checked against the stock search in `tests/test_fast_lanes.py`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from highway_env.road.lane import AbstractLane, CircularLane, SineLane, StraightLane
from highway_env.road.road import LaneIndex, RoadNetwork

SLACK = 1e-6  # [m] a bound must exceed the best distance by this much to skip a lane: float rounding is far less
MIN_LANES = 8  # on fewer lanes (a highway's 3 or 4) measuring them all is as fast (benchmarks/lane_search.py)
EVERYWHERE = (-math.inf, -math.inf, math.inf, math.inf, 0.0)  # no bound: the lane is always measured


def _box(lane: AbstractLane) -> tuple[float, float, float, float, float]:
    """(x_lo, y_lo, x_hi, y_hi, pad): the centre line lies in the box, and the lane's distance to any
    point is at least the point's distance to the box less `pad`. `EVERYWHERE` for another lane type,
    or where a distance could be NaN (a parameter not finite, a straight lane of length 0), which
    highway-env's `np.argmin` would pick wherever it is."""
    kind = type(lane)
    if kind is CircularLane:  # the arc lies on its circle
        cx, cy, r = float(lane.center[0]), float(lane.center[1]), float(lane.radius)
        box = (cx - r, cy - r, cx + r, cy + r, 0.0)
        numbers = [lane.start_phase, lane.end_phase]
    elif kind is StraightLane or kind is SineLane:  # |lateral| + overshoot >= the Euclidean distance
        (x0, y0), (x1, y1) = lane.start, lane.end
        pad = abs(float(lane.amplitude)) if kind is SineLane else 0.0  # a sine lane strays this far
        box = (float(min(x0, x1)), float(min(y0, y1)), float(max(x0, x1)), float(max(y0, y1)), pad)
        numbers = [lane.pulsation, lane.phase] if kind is SineLane else []
        if not lane.length > 0:
            return EVERYWHERE
    else:
        return EVERYWHERE
    return box if all(math.isfinite(float(v)) for v in [*box, *numbers]) else EVERYWHERE


class FastLaneNetwork(RoadNetwork):
    """A `RoadNetwork` whose closest-lane search skips lanes that cannot be the closest."""

    _bounds: tuple[list[LaneIndex], list[AbstractLane], np.ndarray, np.ndarray] | None = None

    def add_lane(self, _from: str, _to: str, lane: AbstractLane) -> None:
        self._bounds = None
        super().add_lane(_from, _to, lane)

    def _lane_bounds(self) -> tuple[list[LaneIndex], list[AbstractLane], np.ndarray, np.ndarray]:
        if self._bounds is None:
            indexes, lanes, boxes = [], [], []
            for _from, to_dict in self.graph.items():
                for _to, road_lanes in to_dict.items():
                    for _id, lane in enumerate(road_lanes):
                        indexes.append((_from, _to, _id))
                        lanes.append(lane)
                        boxes.append(_box(lane))
            table = np.array(boxes, dtype=np.float64).reshape(-1, 5)
            self._bounds = indexes, lanes, table[:, :4], table[:, 4]
        return self._bounds

    def get_closest_lane_index(self, position: np.ndarray, heading: float | None = None) -> LaneIndex:
        x, y = float(position[0]), float(position[1])
        if not (math.isfinite(x) and math.isfinite(y)) or (heading is not None and not math.isfinite(heading)):
            return super().get_closest_lane_index(position, heading)  # np.argmin's NaN rule, not ours
        indexes, lanes, box, pad = self._lane_bounds()
        dx = np.maximum(np.maximum(box[:, 0] - x, x - box[:, 2]), 0.0)
        dy = np.maximum(np.maximum(box[:, 1] - y, y - box[:, 3]), 0.0)
        lower = np.hypot(dx, dy) - pad  # 0 for an `EVERYWHERE` lane: a distance is never below 0, so it is measured
        best, best_i = math.inf, -1
        for i in np.argsort(lower, kind="stable").tolist():
            if lower[i] > best + SLACK:
                break
            distance = lanes[i].distance_with_heading(position, heading)
            if not math.isfinite(distance):
                return super().get_closest_lane_index(position, heading)  # np.argmin's NaN rule, not ours
            if distance < best or (distance == best and i < best_i):
                best, best_i = distance, i
        return indexes[best_i]


def use_fast_lanes(network: Any) -> None:
    """Make a plain `RoadNetwork` of `MIN_LANES` lanes or more search them with `FastLaneNetwork` (same
    answers, fewer lanes measured)."""
    if type(network) is RoadNetwork and sum(len(lanes) for to in network.graph.values()
                                            for lanes in to.values()) >= MIN_LANES:
        network.__class__ = FastLaneNetwork
