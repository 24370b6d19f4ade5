"""The fast closest-lane search gives highway-env's lane, tie for tie, in every scenario zodrive builds."""

from __future__ import annotations

import numpy as np
import pytest
from highway_env.road.lane import StraightLane
from highway_env.road.road import RoadNetwork

import zodrive.envs.highway as fast_envs
from zodrive.envs import load_preset, make_env
from zodrive.envs.fast_lanes import MIN_LANES, FastLaneNetwork

SCENARIOS = ["highway-fast", "discrete", "merge", "roundabout", "intersection", "racetrack"]


def _queries(network: RoadNetwork, rng: np.random.Generator) -> list[tuple[np.ndarray, float | None]]:
    """Points where the answer is hard: lane ends and junctions (exact ties), on and off the road, any heading."""
    lanes = [lane for to_dict in network.graph.values() for road in to_dict.values() for lane in road]
    ends = [lane.position(s, 0.0) for lane in lanes for s in (0.0, lane.length)]
    points = np.array(ends)
    lo, hi = points.min(axis=0) - 30.0, points.max(axis=0) + 30.0
    out: list[tuple[np.ndarray, float | None]] = []
    for lane, end in zip([lane for lane in lanes for _ in (0, 1)], ends):
        out.append((np.array(end, dtype=float), None))
        out.append((np.array(end, dtype=float), float(lane.heading_at(0.0))))
    for _ in range(3000):
        heading = None if rng.random() < 0.2 else float(rng.uniform(-4, 4))
        out.append((rng.uniform(lo, hi), heading))
    for lane in lanes:  # near a lane, along it and just past its ends
        for s in rng.uniform(-10, lane.length + 10, size=8):
            point = lane.position(float(s), float(rng.normal(0, 2)))
            out.append((point, float(lane.heading_at(float(s)) + rng.normal(0, 0.3))))
    return out


@pytest.mark.parametrize("name", SCENARIOS)
def test_the_fast_search_finds_highway_env_s_lane(name: str) -> None:
    env = make_env(load_preset(name))
    env.reset(seed=3)
    network = env.unwrapped.road.network
    lanes = sum(len(road) for to_dict in network.graph.values() for road in to_dict.values())
    # zodrive's scenarios search with it from the first vehicle on, but for a highway's 3 or 4 lanes
    assert (type(network) is FastLaneNetwork) == (lanes >= MIN_LANES) == (name not in ("highway-fast", "discrete"))
    network.__class__ = FastLaneNetwork  # the search itself is checked on every road
    rng = np.random.default_rng(0)
    queries = _queries(network, rng)
    for vehicle in env.unwrapped.road.vehicles:
        queries.append((vehicle.position.copy(), vehicle.heading))
    for position, heading in queries:
        assert network.get_closest_lane_index(position, heading) == \
            RoadNetwork.get_closest_lane_index(network, position, heading), (position, heading)


def test_ties_go_to_the_first_lane_and_broken_input_to_highway_env() -> None:
    network = RoadNetwork()
    network.add_lane("a", "b", StraightLane([0, 0], [10, 0]))
    network.add_lane("b", "c", StraightLane([10, 0], [20, 0]))
    network.add_lane("x", "y", StraightLane([10, 0], [20, 0]))  # the same lane twice: every distance ties
    network.__class__ = FastLaneNetwork
    assert network.get_closest_lane_index(np.array([10.0, 0.0]), 0.0) == ("a", "b", 0)  # both ends tie at 0
    assert network.get_closest_lane_index(np.array([15.0, 1.0]), 0.0) == ("b", "c", 0)
    network.add_lane("c", "d", StraightLane([20, 0], [30, 0]))  # a lane added later is searched too
    assert network.get_closest_lane_index(np.array([28.0, 0.0]), 0.0) == ("c", "d", 0)
    nan = np.array([np.nan, 0.0])
    assert network.get_closest_lane_index(nan, 0.0) == RoadNetwork.get_closest_lane_index(network, nan, 0.0)
    with np.errstate(invalid="ignore"):  # a lane of length 0 measures NaN everywhere, and np.argmin picks it
        network.add_lane("p", "q", StraightLane([500, 500], [500, 500]))
        assert network.get_closest_lane_index(np.array([28.0, 0.0]), 0.0) == ("p", "q", 0) == \
            RoadNetwork.get_closest_lane_index(network, np.array([28.0, 0.0]), 0.0)


@pytest.mark.integration
@pytest.mark.parametrize("name", ["intersection", "roundabout"])
def test_same_episode_with_either_search(name: str, monkeypatch) -> None:
    """Same seed and actions: the same observations and rewards, step for step, with highway-env's search."""
    runs = []
    for fast in (True, False):
        if not fast:
            monkeypatch.setattr(fast_envs, "use_fast_lanes", lambda network: None)
        env = make_env(load_preset(name))
        obs, _ = env.reset(seed=11)
        assert (type(env.unwrapped.road.network) is FastLaneNetwork) == fast
        trace = [obs]
        for t in range(40):
            obs, reward, terminated, truncated, _ = env.step([1, 2, 0, 1, 2][t % 5])
            trace += [obs, np.array([reward])]
            if terminated or truncated:
                obs, _ = env.reset(seed=12 + t)
                trace.append(obs)
        runs.append(trace)
    assert len(runs[0]) == len(runs[1])
    for a, b in zip(*runs):
        np.testing.assert_array_equal(a, b)
