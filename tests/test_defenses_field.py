"""The defenses from the field: randomized smoothing (`smooth@SIGMA`) and temporal smoothing (`temporal[@K]`)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.stats import norm

from toys import linear_victim, observations
from zodrive.attacks.victim import Victim
from zodrive.defense import keeps_state, make_defense, parse_defense
from zodrive.defense.randomized import ALPHA, Smoothing
from zodrive.defense.temporal import TemporalMedian
from zodrive.defense.wrappers import RowFilters, defended_victim
from zodrive.envs import load_preset
from zodrive.errors import ZodriveError

FAST = load_preset("highway-fast")


# ------------------------------------------------------------------ names


@pytest.mark.parametrize("written, canonical", [("smooth@0.050", "smooth@0.05"), ("temporal", "temporal@3"),
                                                ("temporal@5", "temporal@5"), ("shield", "shield@0.02")])
def test_a_defense_has_one_name(written: str, canonical: str) -> None:
    assert parse_defense(written) == canonical


@pytest.mark.parametrize("bad", ["smooth", "smooth@0", "smooth@x", "smooth@2", "temporal@1", "temporal@x", "median"])
def test_a_malformed_defense_is_refused_in_one_line(bad: str) -> None:
    with pytest.raises(ZodriveError) as err:
        parse_defense(bad)
    assert "\n" not in str(err.value)


def test_which_defenses_track_an_episode() -> None:
    assert keeps_state("temporal") and keeps_state("kinematic")
    assert not keeps_state("smooth@0.05") and not keeps_state("shield")


# ------------------------------------------------------------------ randomized smoothing


def test_the_vote_of_an_observation_does_not_depend_on_its_batch() -> None:
    smooth, victim = Smoothing(FAST, 0.05), linear_victim(3)
    guarded = smooth.guard(victim)
    obs = observations(4)
    alone = np.stack([guarded.query(o[None])[0] for o in obs])
    np.testing.assert_array_equal(guarded.query(obs), alone)
    np.testing.assert_allclose(alone.sum(axis=1), 1.0, atol=1e-6)  # vote shares
    assert not np.array_equal(guarded.query(obs[:1]), guarded.query(obs[:1] + 1e-3))  # another point, other noise


def test_the_noise_spares_presence_and_keeps_the_box() -> None:
    smooth = Smoothing(FAST, 0.5)
    obs = observations(3)
    cloud = smooth.noise(obs)
    np.testing.assert_array_equal(cloud[..., 0], np.broadcast_to(obs[:, None, :, 0], cloud[..., 0].shape))
    assert cloud.min() >= -1 and cloud.max() <= 1
    assert np.abs(cloud[..., 1:] - obs[:, None, :, 1:]).max() > 0.1


def test_tiny_noise_votes_as_the_policy_does() -> None:
    victim = linear_victim(5)
    obs = observations(20, seed=4)
    shares = Smoothing(FAST, 1e-6).guard(victim).query(obs)
    np.testing.assert_array_equal(shares.argmax(axis=1), victim.query(obs).argmax(axis=1))
    assert (shares.max(axis=1) == 1.0).all()


def test_the_certified_radius_follows_cohen_et_al() -> None:
    smooth = Smoothing(FAST, 0.1)
    unanimous, split = np.eye(5)[[3]], np.array([[0.5, 0.5, 0, 0, 0]])
    lower = ALPHA ** (1 / smooth.votes)  # Clopper-Pearson with every vote for the top action
    assert smooth.certified_radius(unanimous)[0] == pytest.approx(0.1 * norm.ppf(lower) / np.sqrt(20))
    assert smooth.certified_radius(split)[0] == 0.0  # a tie certifies nothing


def test_smoothing_refuses_a_continuous_policy() -> None:
    with pytest.raises(ZodriveError, match="discrete"):
        make_defense("smooth@0.05", load_preset("continuous"))


def test_white_box_access_is_the_expectation_over_the_noise() -> None:
    victim = linear_victim(2)
    guarded = Smoothing(FAST, 0.05).guard(victim)
    x = torch.tensor(observations(2), requires_grad=True)
    out = guarded.differentiable(x)
    np.testing.assert_allclose(out.detach().numpy(), guarded.query(observations(2)), atol=1e-6)  # value: the vote
    out[:, 3].sum().backward()
    assert x.grad is not None and x.grad.abs().sum() > 0  # gradient: the scores' mean over the copies


# ------------------------------------------------------------------ temporal smoothing


def _scene() -> np.ndarray:
    """An ego and three vehicles (presence, x, y, vx, vy), normalized as highway-fast's, one row absent."""
    return np.array([[1, 1.0, 0.33, 0.3, 0.0],
                     [1, 0.10, 0.0, -0.05, 0.0],
                     [1, 0.20, 0.33, 0.02, 0.0],
                     [1, -0.15, -0.33, 0.04, 0.0],
                     [0, 0.0, 0.0, 0.0, 0.0]], dtype=np.float32)


def _moved(scene: np.ndarray, steps: int, filt: TemporalMedian) -> np.ndarray:
    out = scene.copy()
    out[1:, 1] += steps * filt.kx * out[1:, 3]
    out[1:, 4] *= 0
    out[4] = 0
    return out


def test_vehicles_that_move_as_they_should_pass_unchanged() -> None:
    filt = TemporalMedian(FAST, 3)
    scene = _scene()
    filt.reset(scene)
    for t in range(1, 5):
        np.testing.assert_allclose(filt.update(_moved(scene, t, filt)), _moved(scene, t, filt), atol=1e-6)


def test_rows_are_followed_when_the_order_changes() -> None:
    filt = TemporalMedian(FAST, 3)
    scene = _scene()
    filt.reset(scene)
    filt.update(_moved(scene, 1, filt))
    now = _moved(scene, 2, filt)[[0, 3, 1, 2, 4]]  # the list re-sorted: rows are other vehicles now
    np.testing.assert_allclose(filt.update(now), now, atol=1e-6)


def test_a_one_step_jump_is_removed_and_a_held_one_is_not() -> None:
    filt = TemporalMedian(FAST, 3)
    scene = _scene()
    filt.reset(scene)
    filt.update(_moved(scene, 1, filt))
    jumped = _moved(scene, 2, filt)
    jumped[1, 1] += 0.05  # 10 m further, once
    assert filt.peek(jumped[None])[0, 1, 1] == pytest.approx(_moved(scene, 2, filt)[1, 1], abs=1e-6)
    held = TemporalMedian(FAST, 3)
    shifted = [_moved(scene, t, held) for t in range(4)]
    for s in shifted:
        s[1, 1] += 0.05  # the same 10 m at every step: the median of shifted sightings is shifted
    held.reset(shifted[0])
    outs = [held.update(s) for s in shifted[1:]]
    assert outs[-1][1, 1] == pytest.approx(shifted[-1][1, 1], abs=1e-6)


def test_peek_leaves_the_history_alone() -> None:
    filt = TemporalMedian(FAST, 3)
    scene = _scene()
    filt.reset(scene)
    before = [s.copy() for s in filt.state]
    filt.peek(np.stack([scene + 0.1, scene - 0.1]))
    for a, b in zip(before, filt.state):
        np.testing.assert_array_equal(a, b)


def test_the_attacker_queries_the_smoothed_observation() -> None:
    seen: list[np.ndarray] = []

    def query(batch: np.ndarray) -> np.ndarray:
        seen.append(np.array(batch))
        return np.zeros((len(batch), 5), dtype=np.float32)

    filt = TemporalMedian(FAST, 3)
    scene = _scene()
    filt.reset(scene)
    filt.update(_moved(scene, 1, filt))
    jumped = _moved(scene, 2, filt)
    jumped[1, 1] += 0.05
    defended_victim(Victim(query=query, kind="discrete", obs_shape=(5, 5)), filt).query(jumped[None])
    assert seen[0][0, 1, 1] == pytest.approx(_moved(scene, 2, filt)[1, 1], abs=1e-6)


def test_rows_side_by_side_each_see_their_own_episode() -> None:
    """Lockstep's `RowFilters`: each row's queries through its own filter, as that filter alone would show
    them; a row that starts again forgets its episode; dropped rows take their filters with them."""
    rows = RowFilters(lambda: TemporalMedian(FAST, 3))
    scene = _scene()
    other = scene.copy()
    other[1, 1] += 0.03
    for row, first in enumerate((scene, other)):
        rows.start(row)
        rows.receive(row, first)
    alone = [TemporalMedian(FAST, 3), TemporalMedian(FAST, 3)]
    alone[0].reset(scene)
    alone[1].reset(other)
    queries = np.stack([_moved(scene, 1, alone[0]), _moved(other, 1, alone[1]), _moved(scene, 1, alone[0]) + 0.01])
    owners = np.array([1, 0, 0])
    seen = rows.peek(queries, owners)
    for q, row in enumerate(owners):
        np.testing.assert_array_equal(seen[q], alone[row].peek(queries[q:q + 1])[0])
    assert not np.array_equal(seen[0], rows.peek(queries[:1], np.array([0]))[0])  # another row, another history
    rows.start(0)  # a new episode on row 0: nothing to compare with
    np.testing.assert_array_equal(rows.peek(queries[:1], np.array([0])), queries[:1])
    rows.keep_rows(np.array([1]))
    np.testing.assert_array_equal(rows.peek(queries[:1], np.array([0])), seen[:1])  # row 1 is row 0 now


def test_temporal_smoothing_refuses_what_it_cannot_follow() -> None:
    grid = {"name": "grid", "env_id": "zodrive/highway-v0",
            "highway": {"observation": {"type": "OccupancyGrid"}}}
    with pytest.raises(ZodriveError):
        make_defense("temporal", grid)
