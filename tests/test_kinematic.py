"""The kinematic-consistency filter: clean driving passes, teleports do not."""

from __future__ import annotations

import numpy as np
import pytest

from toys import context, linear_victim
from zodrive.attacks import AttackSpec
from zodrive.defense import make_defense
from zodrive.defense.kinematic import KinematicFilter
from zodrive.defense.wrappers import FilterWrapper, defended_victim
from zodrive.envs import load_preset, make_env
from zodrive.errors import ZodriveError

PRESET = load_preset("discrete")


def _clean_steps(n: int = 120, seed: int = 50_000) -> list[np.ndarray]:
    env, rng = make_env(PRESET), np.random.default_rng(0)
    obs, _ = env.reset(seed=seed)
    seen = [obs]
    for _ in range(n):
        obs, _, done, trunc, _ = env.step(int(rng.choice([1, 1, 1, 4, 0, 2])))
        seen.append(obs)
        if done or trunc:
            break
    return seen


def test_clean_observations_pass_almost_unchanged() -> None:
    filt = KinematicFilter(PRESET)
    steps = _clean_steps()
    filt.reset(steps[0])
    changes = [np.abs(filt.update(obs) - obs).max() for obs in steps[1:]]
    assert np.percentile(changes, 95) < 1e-6  # physics as observed: nothing to correct
    assert max(changes) < 0.05


def test_a_teleport_is_held_to_what_physics_allows() -> None:
    filt = KinematicFilter(PRESET)
    steps = _clean_steps(10)
    filt.reset(steps[0])
    for obs in steps[1:5]:
        filt.update(obs)
    jumped = steps[5].copy()
    jumped[1, 1] += 0.2   # the nearest vehicle 20 m further away in one step
    jumped[1, 3] -= 0.2   # and 4 m/s slower
    out = filt.update(jumped)
    assert abs(out[1, 1] - steps[5][1, 1]) <= 2 * filt.tol.x + 1e-6
    assert abs(out[1, 3] - steps[5][1, 3]) <= 2 * filt.tol.vx + 1e-6  # prediction +- tol; the truth within tol of it
    np.testing.assert_array_equal(out[:, 0], jumped[:, 0])  # presence is trusted


def test_peek_does_not_advance_the_state() -> None:
    filt = KinematicFilter(PRESET)
    steps = _clean_steps(5)
    filt.reset(steps[0])
    before = filt.state.copy()
    batch = np.stack([steps[1], steps[2] + 0.1])
    assert filt.peek(batch).shape == batch.shape
    np.testing.assert_array_equal(filt.state, before)


def test_the_attacker_queries_the_defended_system_and_the_policy_sees_filtered_observations() -> None:
    victim = linear_victim()
    filt = make_defense("kinematic", PRESET)
    calls: list[np.ndarray] = []
    inner = defended_victim(victim, filt)
    spied = type(inner)(query=lambda b: (calls.append(b.copy()), inner.query(b))[1], kind="discrete", obs_shape=(5, 5))
    from zodrive.system import make_attacked_env

    env = FilterWrapper(make_attacked_env(PRESET, spied, AttackSpec(steps=5, n_directions=4, eps=0.2)), filt)
    obs, info = env.reset(seed=3)
    for _ in range(5):
        obs, _, _, _, info = env.step(1)
        assert np.abs(obs - filt.state).max() == 0  # what the policy gets is the filter's estimate
    assert calls and np.abs(obs - info["clean_obs"]).max() <= 0.2 + 1e-6


def test_unknown_defense_and_unsupported_observation_are_errors() -> None:
    with pytest.raises(ZodriveError, match="unknown defense"):
        make_defense("magic", PRESET)
    with pytest.raises(ZodriveError, match="relative, normalized"):
        KinematicFilter(load_preset("discrete", ["highway.observation.absolute=true"]))


def test_white_box_pgd_reaches_through_the_filter_by_bpda() -> None:
    victim = linear_victim(seed=2)
    filt = KinematicFilter(PRESET)
    steps = _clean_steps(6)
    filt.reset(steps[0])
    for obs in steps[1:5]:
        filt.update(obs)
    defended = defended_victim(victim, filt)
    x = np.stack([steps[5], steps[5] + 0.05]).astype(np.float32)
    import torch

    t = torch.tensor(x, requires_grad=True)
    out = defended.differentiable(t)
    np.testing.assert_allclose(out.detach().numpy(), victim.query(filt.peek(x)), atol=1e-5)  # forward: filter, net
    out.sum().backward()
    assert t.grad is not None and np.abs(t.grad.numpy()).sum() > 0  # backward: not the clamp's zeros
    attack, objective, oracle = AttackSpec(attack="pgd", eps=0.2, target="none").build(defended, **context())
    result = attack.perturb(x[:1], oracle, objective)
    before = objective.loss(torch.from_numpy(defended.query(x[:1]))[:, None], torch.from_numpy(result.clean_outputs))
    after = objective.loss(torch.from_numpy(defended.query(result.x_adv))[:, None],
                           torch.from_numpy(result.clean_outputs))
    assert float(after) < float(before)  # the gradient through the filter leads somewhere: the loss falls
