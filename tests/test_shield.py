"""The certified safety shield (`--defense shield[@EPS]`): hand-built observations, no long runs."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from zodrive.agents.rules import FASTER, IDLE, LANE_LEFT, LANE_RIGHT, SLOWER, ObservationRules
from zodrive.attacks.victim import Victim
from zodrive.defense import parse_defense
from zodrive.defense.shield import DEFAULT_EPS, Shield, shielded_victim
from zodrive.envs import load_preset
from zodrive.errors import ZodriveError

PRESET = load_preset("discrete")


def _road() -> tuple[np.ndarray, np.ndarray]:
    """A free road (alone in lane 2, centred, at >= 20 m/s) and the same with a car 12 m ahead,
    2 m/s slower, in the own lane."""
    free = np.zeros((1, 5, 5), np.float32)
    free[0, 0] = [1, 1, 0.08, 1, 0]
    close = free.copy()
    close[0, 1] = [1, 0.12, 0, -0.1, 0]
    return free, close


def _truths(n: int, rng: np.random.Generator) -> np.ndarray:
    """Random true observations: the ego centred in a lane, up to four vehicles around it."""
    truth = np.zeros((n, 5, 5), np.float32)
    truth[:, 0] = [1, 0.5, 0, 1, 0]
    truth[:, 0, 2] = rng.integers(0, 4, n) * 0.04
    truth[:, 1:, 0] = rng.random((n, 4)) < 0.8
    truth[:, 1:, 1] = rng.uniform(-0.15, 0.9, (n, 4))                   # -15 .. 90 m
    truth[:, 1:, 2] = rng.integers(-2, 3, (n, 4)) * 0.04 + rng.uniform(-0.015, 0.015, (n, 4))
    truth[:, 1:, 3] = rng.uniform(-0.3, 0.1, (n, 4))
    truth[:, 1:, 4] = rng.uniform(-0.05, 0.05, (n, 4))
    return truth


def test_unsafe_faster_is_replaced_and_safe_faster_passes() -> None:
    shield = Shield(PRESET, 0.02)
    free, close = _road()
    both = np.concatenate([free, close])
    out = shield.decide(both, np.array([FASTER, FASTER]))
    assert out[0] == FASTER                                   # free road: the driver's FASTER stands
    assert out[1] != FASTER and out[1] in (LANE_LEFT, LANE_RIGHT, SLOWER)  # close behind a car: vetoed
    assert out[1] == ObservationRules(PRESET, 0.02).actions(close)[0]    # ... for the robust rules' choice
    assert shield.decide(close, np.array([SLOWER]))[0] == SLOWER        # braking is always allowed
    assert shield.decide(close, np.array([IDLE]))[0] != IDLE            # keeping speed into it is not
    edge = free.copy()
    edge[0, 0, 2] = 0.12                                                 # truly in the rightmost lane (3)
    seen = edge.copy()
    seen[0, 0, 2] -= 0.02                                                # seen 2 m to the left: "lane 2"
    assert ObservationRules(PRESET).safe_actions(seen)[0, LANE_RIGHT]   # the plain test is fooled
    assert shield.decide(seen, np.array([LANE_RIGHT]))[0] != LANE_RIGHT  # the shield is not
    blocked = close.copy()
    blocked[0, 2] = [1, 0.02, -0.04, 0, 0]                               # a car beside on the left
    assert shield.decide(blocked, np.array([LANE_LEFT]))[0] != LANE_LEFT


def test_shielded_actions_are_safe_for_every_corner_of_the_eps_box() -> None:
    """Under any perturbation of budget eps of the other vehicles' rows (here: corners of the
    box, the attacker's random-search vertices), whatever the driver proposes, the shield's
    action is one the plain rules' test accepts on the true observation."""
    rng = np.random.default_rng(0)
    for eps in (0.02, 0.05):
        shield, truth_test = Shield(PRESET, eps), ObservationRules(PRESET, 0.0)
        truth = _truths(2000, rng)
        safe_truth = truth_test.safe_actions(truth)
        passed = vetoed = 0
        for _ in range(8):
            seen = truth.copy()  # every row, the ego's too (its lateral position picks the lanes)
            seen[:, :, 1:] += rng.choice([-eps, eps], size=(len(truth), 5, 4)).astype(np.float32)
            proposed = rng.integers(0, 5, len(truth))
            final = shield.decide(seen, proposed)
            assert safe_truth[np.arange(len(truth)), final].all()
            passed += int(((final == proposed) & (proposed != SLOWER)).sum())
            vetoed += int((final != proposed).sum())
        assert passed > 500 and vetoed > 500                 # neither a brake nor a pass-through
    # the guarantee is the shield's, not the test's: the plain rules (eps 0) as a shield fail it
    plain = Shield.__new__(Shield)
    plain.rules, plain.eps = ObservationRules(PRESET, 0.0), 0.0
    seen = truth.copy()
    seen[:, 1:, 1:] += rng.choice([-0.05, 0.05], size=(len(truth), 4, 4)).astype(np.float32)
    final = plain.decide(seen, np.full(len(truth), FASTER))
    assert not safe_truth[np.arange(len(truth)), final].all()


def test_the_fallback_is_always_safe_and_plain_rules_decisions_are_unchanged() -> None:
    rng = np.random.default_rng(1)
    seen = _truths(5000, rng)
    seen[:, 0, 2] += rng.uniform(-0.02, 0.02, len(seen))   # off-centre egos too
    act = ObservationRules(PRESET).actions(seen)
    assert ObservationRules(PRESET).safe_actions(seen)[np.arange(len(seen)), act].all()
    for eps in (0.02, 0.05):
        shield = Shield(PRESET, eps)
        assert shield.safe(seen)[np.arange(len(seen)), shield.fallback(seen)].all()
    free, close = _road()
    assert ObservationRules(PRESET).actions(np.concatenate([free, close])).tolist() == [LANE_RIGHT, LANE_LEFT]


def test_defended_outputs_pick_the_shielded_action_and_pgd_gets_gradients() -> None:
    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Flatten(), torch.nn.Linear(25, 5))
    with torch.no_grad():
        net[1].bias.copy_(torch.tensor([0.0, 0.0, 0.0, 5.0, 0.0]))  # a driver that wants FASTER
    driver = Victim(query=lambda b: net(torch.as_tensor(b, dtype=torch.float32)).detach().numpy(),
                    kind="discrete", obs_shape=(5, 5), differentiable=lambda x: net(x.float()))
    shield = Shield(PRESET, 0.02)
    defended = shielded_victim(driver, shield)
    rng = np.random.default_rng(2)
    obs = _truths(500, rng)
    scores, out = driver.query(obs), defended.query(obs)
    assert np.isfinite(out).all()
    np.testing.assert_array_equal(out.argmax(-1), shield.decide(obs, scores.argmax(-1)))
    keep = shield.decide(obs, scores.argmax(-1)) == FASTER
    assert 0 < keep.sum() < len(obs)
    safe = shield.safe(obs)
    final = shield.decide(obs, scores.argmax(-1))
    vetoed = final != scores.argmax(-1)
    kept = safe.copy()
    kept[np.nonzero(vetoed)[0], final[vetoed]] = False           # the fallback is lifted above the row
    np.testing.assert_allclose(out[kept], scores[kept], rtol=1e-6)   # allowed actions keep the driver's scores
    assert (out[~safe] < scores.min(-1, keepdims=True).repeat(5, 1)[~safe]).all()  # vetoed ones sink below all
    x = torch.tensor(obs, requires_grad=True)
    value = defended.differentiable(x)
    np.testing.assert_allclose(value.detach().numpy(), out, rtol=1e-6)
    value[:, FASTER].sum().backward()
    assert x.grad is not None and x.grad.abs().sum() > 0                # BPDA: the driver network's gradient


def test_names_budgets_and_presets() -> None:
    assert parse_defense("shield") == f"shield@{DEFAULT_EPS:g}" == "shield@0.02"
    assert parse_defense("shield@.050") == "shield@0.05"
    assert parse_defense("kinematic") == "kinematic"
    for bad in ("shield@0", "shield@1", "shield@x", "shield@nan", "shield@-0.1", "shield@", "magic"):
        with pytest.raises(ZodriveError):
            parse_defense(bad)
    with pytest.raises(ZodriveError, match="discrete"):
        Shield(load_preset("continuous"))
    with pytest.raises(ZodriveError, match="relative, normalized"):
        Shield(load_preset("discrete", ["highway.observation.absolute=true"]))


@pytest.mark.parametrize("defense", ["shield@2", "shield@abc", "shieldx"])
def test_bad_defense_on_the_command_line_is_one_line(defense: str, capsys: pytest.CaptureFixture[str]) -> None:
    from zodrive.cli import main

    assert main(["evaluate", "baseline:rules", "--episodes", "1", "--defense", defense]) == 2
    err = capsys.readouterr().err
    assert err.startswith("zodrive: error:") and err.count("\n") == 1 and "Traceback" not in err


def test_shield_on_a_continuous_policy_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    from zodrive.cli import main

    assert main(["evaluate", "baseline:brake", "--preset", "continuous", "--episodes", "1", "--defense", "shield"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "discrete" in err


def test_the_policy_env_drives_with_the_shield() -> None:
    from zodrive.agents.policies import make_policy_env
    from zodrive.evaluation.rollout import act

    victim, env = make_policy_env("baseline:rules", load_preset("discrete", ["max_episode_steps=5"]),
                                  defense="shield@0.05")
    obs, _ = env.reset(seed=100000)
    shield = Shield(PRESET, 0.05)
    action = act(victim, obs, env.action_space)
    assert shield.safe(obs[None])[0, int(action)]
    env.close()
