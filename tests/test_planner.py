"""`baseline:planner`: its rollouts are the future they stand for, and it picks the best one."""

from __future__ import annotations

import numpy as np
import pytest

from zodrive.drivers import planner as planner_module
from zodrive.drivers.planner import FASTER, IDLE, LANE_LEFT, LANE_RIGHT, SLOWER, LookAheadPlanner
from zodrive.cli import main
from zodrive.envs import load_preset, make_env


def _driven_env(steps: int = 20):
    preset = load_preset("discrete")
    env = make_env(preset)
    env.reset(seed=50_000)
    planner = LookAheadPlanner(env, preset, horizon_s=1.0)
    for _ in range(steps):
        env.step(IDLE)
    return env, planner


def test_a_rollout_scores_what_the_real_environment_then_pays() -> None:
    """A pruned copy's rollout (the action, then the rules) sums the very rewards the real
    environment pays when driven the same way: the copy is exact, the pruning drops nothing that matters."""
    env, planner = _driven_env()
    for action in (FASTER, LANE_LEFT):
        predicted = planner._rollout(env.unwrapped, action)
        real = make_env(load_preset("discrete"))  # the same state again, driven for real
        real.reset(seed=50_000)
        for _ in range(20):
            real.step(IDLE)
        total, a = 0.0, action
        for _ in range(planner.steps):
            obs, reward, terminated, truncated, info = real.step(a)
            total += float(reward)
            assert not info["crashed"]
            a = int(planner.rules.actions(np.asarray(obs, np.float32)[None])[0])
        assert predicted == pytest.approx(total, abs=1e-9)
    assert planner.steps == 15  # 1 s at 15 Hz


def test_it_takes_the_best_rollout_and_the_rules_action_on_a_tie(monkeypatch) -> None:
    env, planner = _driven_env(1)
    own = int(planner.rules.actions(np.asarray(env.unwrapped.observation_type.observe(), np.float32)[None])[0])
    monkeypatch.setattr(planner, "_rollout", lambda base, action: 1.0)
    assert planner() == own
    best = next(a for a in planner.candidates(env.unwrapped) if a != own)
    monkeypatch.setattr(planner, "_rollout", lambda base, action: 2.0 if action == best else 1.0)
    assert planner() == best


def test_only_actions_that_differ_are_tried() -> None:
    env, planner = _driven_env(1)
    ego = env.unwrapped.vehicle
    lane = ego.target_lane_index[2]
    tried = set(planner.candidates(env.unwrapped))
    assert (LANE_LEFT in tried) == (lane > 0) and (LANE_RIGHT in tried) == (lane < 3) and IDLE in tried
    ego.target_speed = ego.target_speeds[-1]  # at the top target speed FASTER does what IDLE does
    assert FASTER not in planner.candidates(env.unwrapped) and SLOWER in planner.candidates(env.unwrapped)
    assert planner_module.CRASH_SCORE < -450  # a crash is worse than any 450-step return


@pytest.mark.parametrize(("args", "message"), [
    (["evaluate", "baseline:planner", "--preset", "continuous"], "drives discrete presets"),
    (["evaluate", "baseline:planner", "--attack", "random-search"], "reads the simulator"),
    (["evaluate", "baseline:planner", "--env-id", "CartPole-v1"], "on a highway-env road"),
])
def test_planner_refuses_what_it_cannot_do(args: list[str], message: str, capsys) -> None:
    assert main(args) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def test_off_the_straight_highway_it_holds_idle_after_each_first_action() -> None:
    """Intersection (three longitudinal meta-actions, a route): every available action is tried, then IDLE
    held; what it picks scores best in a copy, and the real episode is driven without a crash."""
    preset = load_preset("intersection")
    env = make_env(preset)
    env.reset(seed=50_000)
    planner = LookAheadPlanner(env, preset, horizon_s=2.0, straight=False)
    base = env.unwrapped
    idle = base.action_type.actions_indexes["IDLE"]
    scores = {int(a): planner._rollout(base, int(a)) for a in base.action_type.get_available_actions()}
    choice = planner()
    assert scores[choice] == max(scores.values()) and (choice == idle or scores[choice] > scores[idle])
    assert len(scores) >= 2 and set(base.action_type.actions.values()) == {"SLOWER", "IDLE", "FASTER"}
