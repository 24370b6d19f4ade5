"""The round-cached neighbour search gives highway-env's leader and follower, call for call, in every scenario."""

from __future__ import annotations

import numpy as np
import pytest
from highway_env.road.lane import StraightLane
from highway_env.road.road import Road, RoadNetwork
from highway_env.vehicle.behavior import IDMVehicle

import zodrive.envs.highway as fast_envs
from zodrive.envs import load_preset, make_env
from zodrive.envs.fast_neighbours import FAST_ROADS, FastNeighbourRoad, use_fast_neighbours

SCENARIOS = ["highway-fast", "merge", "roundabout", "intersection"]


@pytest.mark.parametrize("name", SCENARIOS)
def test_every_question_of_a_round_gets_highway_env_s_answer(name: str, monkeypatch) -> None:
    """Every call the vehicles make while deciding, and the same question for every lane of the road, is
    answered as `Road.neighbour_vehicles` answers it at that moment."""
    env = make_env(load_preset(name))
    env.reset(seed=7)
    road = env.unwrapped.road
    assert (type(road) in FAST_ROADS.values()) == (name == "highway-fast")  # zodrive's highway searches with it
    use_fast_neighbours(road)  # the search itself is checked on every road
    assert type(road) in FAST_ROADS.values()
    lanes = [(a, b, i) for a, to in road.network.graph.items() for b, group in to.items() for i in range(len(group))]
    fast_search = FastNeighbourRoad.neighbour_vehicles
    calls = []

    def checked(self, vehicle, lane_index=None):
        answer = fast_search(self, vehicle, lane_index)
        assert answer == Road.neighbour_vehicles(self, vehicle, lane_index)
        calls.append(answer)
        if len(calls) % 25 == 1:  # now and then every lane of the road, asked for this vehicle
            for other in lanes:
                assert fast_search(self, vehicle, other) == Road.neighbour_vehicles(self, vehicle, other), other
        return answer

    monkeypatch.setattr(FastNeighbourRoad, "neighbour_vehicles", checked)
    rng = np.random.default_rng(0)
    for _ in range(4):
        _, _, terminated, truncated, _ = env.step(int(rng.integers(env.action_space.n)))
        if terminated or truncated:
            env.reset(seed=8)
    assert len(calls) > 50  # the vehicles did ask
    assert any(front is not None for front, _ in calls) and any(rear is not None for _, rear in calls)


def test_ties_and_a_question_outside_a_round() -> None:
    """Two vehicles at the same spot: highway-env's order decides (the later one in front, the earlier
    behind); asked outside `act`, the road asks highway-env."""
    network = RoadNetwork()
    network.add_lane("a", "b", StraightLane([0, 0], [500, 0]))
    road = Road(network=network)
    ego, twin, other, far = (IDMVehicle(road, [x, y]) for x, y in ((100, 0), (150, 0), (150, 0), (150, 9)))
    road.vehicles.extend([ego, twin, other, far])
    road.__class__ = FastNeighbourRoad
    stock = Road.neighbour_vehicles(road, ego)
    assert road.neighbour_vehicles(ego) == stock  # outside a round
    road._entities, road._round = road.vehicles + road.objects, {}  # as `act` sets them
    assert road.neighbour_vehicles(ego) == stock == (other, None)  # s_v <= s_front: the later one wins
    assert road.neighbour_vehicles(twin) == Road.neighbour_vehicles(road, twin) == (other, ego)
    assert len(road._round) == 1  # one lane projected, once


@pytest.mark.integration
@pytest.mark.parametrize("name", ["highway-fast"])
def test_same_episode_with_either_search(name: str, monkeypatch) -> None:
    """Same seed and actions: the same observations and rewards, step for step, with highway-env's search."""
    runs = []
    for fast in (True, False):
        if not fast:
            monkeypatch.setattr(fast_envs, "use_fast_neighbours", lambda road: None)
        env = make_env(load_preset(name))
        rng = np.random.default_rng(1)
        seen = []
        for seed in (11, 12):
            obs, _ = env.reset(seed=seed)
            seen.append(obs)
            for _ in range(40):
                obs, reward, terminated, truncated, _ = env.step(int(rng.integers(env.action_space.n)))
                seen += [obs, np.array([reward, terminated, truncated])]
                if terminated or truncated:
                    break
        runs.append(seen)
    assert len(runs[0]) == len(runs[1])
    assert all(np.array_equal(a, b) for a, b in zip(*runs))
