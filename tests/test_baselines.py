"""Built-in baselines stand wherever a model can, and driving metrics say how a policy drives."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from zodrive.drivers.baselines import BASELINES
from zodrive.policies.policy import resolve
from zodrive.policies.resolve import load_victim
from zodrive.system import make_policy_env
from zodrive.cli import main
from zodrive.envs import load_preset
from zodrive.evaluation.rollout import run_episode

SHORT = ["max_episode_steps=60"]


def test_constant_baselines_ignore_their_input() -> None:
    preset = load_preset("discrete")
    victim = load_victim("baseline:slower", preset)
    obs = np.random.default_rng(0).uniform(-1, 1, (7, 5, 5)).astype(np.float32)
    assert victim.actions(victim.query(obs)).tolist() == [4] * 7
    assert victim.reads == "nothing"
    brake = load_victim("baseline:brake", load_preset("continuous"))
    np.testing.assert_array_equal(brake.query(obs[:2]), [[-1, 0], [-1, 0]])


def test_idm_mobil_drives_and_changes_lanes() -> None:
    """The rule-based driver keeps going without a crash on these seeds, overtakes and speeds up."""
    preset = load_preset("discrete", ["max_episode_steps=150"])
    victim, env = make_policy_env("baseline:idm-mobil", preset)
    records = [run_episode(env, victim, episode=i, seed=50_000 + i, max_return=150.0) for i in range(2)]
    assert not any(r.crashed for r in records)
    assert sum(r.lane_changes for r in records) >= 1
    assert all(r.mean_speed > 20.5 for r in records)  # faster than always-SLOWER
    counts = np.sum([r.action_counts for r in records], axis=0)
    assert counts[3] > 0 and counts[1] > counts[4]  # it accelerates and mostly holds


def test_idm_mobil_continuous_stays_on_the_road() -> None:
    preset = load_preset("continuous", ["max_episode_steps=150"])
    victim, env = make_policy_env("baseline:idm-mobil", preset)
    record = run_episode(env, victim, episode=0, seed=50_000, max_return=150.0)
    assert not record.offroad and not record.crashed and record.length == 150
    assert record.distance > 150 * 20.0 / 15  # [m] at more than 20 m/s on average


def test_observation_rules_drive_and_can_be_attacked_on_their_decisions() -> None:
    """`baseline:rules` reads the observation: it speeds up on free road, brakes behind a close
    car, and an attack that changes its observation changes what it does."""
    from zodrive.drivers.rules import FASTER, LANE_LEFT, SLOWER, ObservationRules
    from zodrive.attacks import AttackSpec
    from zodrive.envs import attack_context

    preset = load_preset("discrete", ["max_episode_steps=150"])
    rules = ObservationRules(preset)
    free = np.zeros((1, 5, 5), np.float32)
    free[0, 0] = [1, 1, 0.12, 1, 0]  # alone in the right lane (3) at >= 20 m/s
    close = free.copy()
    close[0, 1] = [1, 0.12, 0, -0.1, 0]  # a car 12 m ahead in the own lane, 2 m/s slower
    blocked = close.copy()
    blocked[0, 2] = [1, 0.02, -0.04, 0, 0]  # and one beside on the left
    middle = free.copy()
    middle[0, 0, 2] = 0.08  # alone in lane 2: keep right
    assert rules.actions(np.concatenate([free, close, blocked, middle])).tolist() == [FASTER, LANE_LEFT, SLOWER, 2]
    victim, env = make_policy_env("baseline:rules", preset)
    assert victim.reads == "observation" and victim.differentiable is None
    record = run_episode(env, victim, episode=0, seed=50_000, max_return=150.0)
    assert record.mean_speed > 20.5 and not record.crashed
    attack, objective, oracle = AttackSpec(attack="random-search", eps=0.2).build(victim, **attack_context(preset))
    result = attack.perturb(close, oracle, objective)  # make it speed into the car ahead
    assert result.success[0] and victim.actions(victim.query(result.x_adv))[0] == FASTER


def test_continuous_rules_keep_the_lane_follow_and_finish_a_change() -> None:
    """`baseline:rules` on the continuous preset: on a free road it accelerates and steers back
    to the lane centre; behind a close, slower car it brakes; while it moves sideways it keeps
    heading for the next lane centre in that direction (no memory needed to finish a change);
    and it drives the real environment without a crash or leaving the road."""
    from zodrive.drivers.rules import ContinuousRules

    preset = load_preset("continuous", ["max_episode_steps=150"])
    driver = ContinuousRules(preset)
    free = np.zeros((1, 5, 5), np.float32)
    free[0, 0] = [1, 1, 0.12, 1, 0]  # centred in the right lane (3) at >= 20 m/s (observed 20)
    right_of_centre = free.copy()
    right_of_centre[0, 0, 2] = 0.13  # 1 m right of the lane centre
    close = free.copy()
    close[0, 1] = [1, 0.15, 0, -0.2, 0]  # a car 15 m ahead in the own lane, 4 m/s slower
    leaving = free.copy()
    leaving[0, 0, 2:5] = [0.105, 1, -0.1]  # 1.5 m left of lane 3's centre, moving left at 2 m/s
    acc, steer = driver.controls(np.concatenate([free, right_of_centre, close, leaving])).T
    assert acc[0] > 0 and steer[0] == pytest.approx(0, abs=1e-4)  # (float32 rounding of y)
    assert steer[1] < 0  # back towards the centre, to the left
    assert acc[2] < 0  # brakes behind the close car
    assert steer[3] < 0  # on to lane 2 (2.5 m further left), not back to lane 3
    victim, env = make_policy_env("baseline:rules", preset)
    assert victim.kind == "continuous" and victim.reads == "observation"
    record = run_episode(env, victim, episode=0, seed=50_000, max_return=150.0)
    assert not record.crashed and not record.offroad and record.length == 150
    assert record.distance > 150 * 20.0 / 15  # [m] at more than 20 m/s on average


def test_driving_metrics_of_a_constant_policy() -> None:
    preset = load_preset("discrete", SHORT)
    victim, env = make_policy_env("baseline:slower", preset)
    record = run_episode(env, victim, episode=0, seed=3, max_return=60.0)
    assert record.lane_changes == 0  # SLOWER never steers
    assert record.distance == pytest.approx(record.mean_speed * record.length / 15, rel=0.05)


def test_policy_names() -> None:
    assert resolve("baseline:brake").action_kind() == "continuous"
    assert resolve("baseline:idm-mobil").action_kind() == "discrete"
    assert resolve("baseline:idle").label == "baseline:idle"
    assert {"slower", "idle", "brake", "idm-mobil"} <= set(BASELINES)


def test_evaluate_a_baseline(tmp_path: Path, capsys) -> None:
    out = tmp_path / "brake"
    assert main(["evaluate", "baseline:brake", "--episodes", "2", "--out", str(out), "--no-progress",
                 "--env-set", SHORT[0]]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["model"] == "baseline:brake" and summary["preset"] == "continuous"
    for key in ("mean_speed", "lane_changes_per_episode", "mean_distance", "right_lane_share", "offroad_rate"):
        assert key in summary
    assert summary["mean_speed"] < 18.0  # full brake: from 25 m/s down to the preset's 15 m/s floor
    assert "lane changes/episode" in capsys.readouterr().out


def test_attacking_a_constant_baseline_is_refused_since_it_changes_nothing(capsys) -> None:
    from zodrive.policies.resolve import load_victim
    from zodrive.envs import load_preset

    victim = load_victim("baseline:slower", load_preset("discrete"))
    obs = np.random.default_rng(0).uniform(-1, 1, (64, 5, 5)).astype(np.float32)
    assert (victim.query(obs) == victim.query(np.zeros_like(obs))).all()  # no observation moves it
    args = ["evaluate", "baseline:slower", "--episodes", "1", "--attack", "random-search", "--steps", "3"]
    assert main(args) == 2  # so spending queries on it is refused, in one line
    err = capsys.readouterr().err
    assert "constant action" in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize(("args", "message"), [
    (["evaluate", "baseline:nosuch"], "known: baseline:slower"),
    (["evaluate", "baseline:brake", "--preset", "discrete"], "drives continuous presets"),
    (["evaluate", "baseline:close-rules", "--preset", "continuous"], "drives discrete presets"),
    (["evaluate", "baseline:close-rules@0.05"], "take @EPS"),
    (["evaluate", "baseline:idm-mobil", "--attack", "zo-signsgd"], "reads the simulator"),
    (["render", "baseline:idm-mobil", "--attack", "nes", "--out", "x"], "reads the simulator"),
])
def test_bad_baselines(args: list[str], message: str, capsys) -> None:
    assert main(args) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def test_card_reports_median_and_range_over_training_seeds(tmp_path: Path) -> None:
    from zodrive.experiments.card import seed_table

    runs = []
    for seed, ret, speed in ((0, 300.0, 24.0), (1, 360.0, 26.0), (2, 340.0, 25.0)):
        run = tmp_path / f"seed{seed}"
        (run / "eval").mkdir(parents=True)
        (run / "train.json").write_text(json.dumps({"seed": seed}))
        (run / "eval" / "summary.json").write_text(json.dumps({
            "mean_return": ret, "ci95": [ret - 5, ret + 5], "collision_rate": 0.01, "offroad_rate": 0.0,
            "mean_speed": speed, "lane_changes_per_episode": 1.5}))
        episodes = [{"seed": 100 + i, "return": ret + (i % 5 - 2)} for i in range(20)]
        (run / "eval" / "episodes.jsonl").write_text("".join(json.dumps(e) + "\n" for e in episodes))
        runs.append(run)
    text = "\n".join(seed_table(runs))
    assert "Mean return across 3 seeds: median 340.00, range 300.00–360.00" in text
    assert "Speed (m/s) across 3 seeds: median 25.0, range 24.0–26.0" in text
    iqm = re.search(r"Interquartile mean over 3 seeds x 20 episodes .*: ([\d.]+) \(([\d.]+)–([\d.]+)\)", text)
    assert iqm, text
    low, point, high = float(iqm.group(2)), float(iqm.group(1)), float(iqm.group(3))
    assert 300 <= low <= point <= high <= 360 and low < high


def test_learning_curves_bin_episodes_by_training_step(tmp_path: Path, capsys) -> None:
    run = tmp_path / "run"
    run.mkdir()
    rows = "\n".join(f"{r},{n},0.0" for r, n in ((10, 50), (20, 50), (300, 100), (100, 40)))
    (run / "monitor.monitor.csv").write_text('#{"t_start": 0}\nr,l,t\n' + rows + "\n")
    assert main(["curves", str(run), "--bin", "100", "--plot", str(tmp_path / "c.png")]) == 0
    out = capsys.readouterr().out
    assert "| run | 15 / 50 | 300 / 100 | 100 / 40 |" in out  # steps 0-100, 100-200, 200-300
    assert (tmp_path / "c.png").stat().st_size > 0
    assert main(["curves", str(tmp_path / "nothing")]) == 2


def test_perception_panel_shows_every_perceived_vehicle() -> None:
    from zodrive.evaluation.video import X_RANGE, Y_RANGE, Frame, panel_extent

    clean = np.zeros((5, 5), dtype=np.float32)
    clean[:, 0] = 1.0
    clean[1:, 1] = [0.2, 0.4, 0.6, 0.8]
    perceived = clean.copy()
    perceived[2, 2] = 0.2   # moved 20 m sideways by an attack
    perceived[3, 1] = -0.5  # moved 50 m behind the ego
    (x_low, x_high), y_half = panel_extent(Frame(np.zeros((2, 2, 3)), clean, perceived, 1))
    for row in perceived[1:]:
        assert x_low < row[1] * X_RANGE < x_high and abs(row[2] * Y_RANGE) < y_half
    assert panel_extent(Frame(np.zeros((2, 2, 3)), clean, clean, 1))[1] == 14.0  # the lanes, as before


def test_robust_rules_never_speed_up_where_the_truth_says_brake() -> None:
    """`baseline:robust-rules@EPS` is pessimistic within the budget: on observations whose other
    vehicles were moved by up to eps (what the guarantee covers), it accelerates only if the plain
    rules on the true observation find the own lane free by their margin; at eps 0 it is the rules."""
    from zodrive.drivers.rules import FASTER, LANE_RIGHT, ObservationRules

    preset = load_preset("discrete")
    rng = np.random.default_rng(0)
    n, eps = 20000, 0.05
    truth = np.zeros((n, 5, 5), np.float32)
    truth[:, 0] = [1, 0.5, 0, 1, 0]
    truth[:, 0, 2] = rng.integers(0, 4, n) * 0.04                       # the ego at a lane centre
    truth[:, 1:, 0] = rng.random((n, 4)) < 0.8
    truth[:, 1:, 1] = rng.uniform(-0.1, 0.9, (n, 4))                    # -10 .. 90 m
    truth[:, 1:, 2] = rng.integers(-2, 3, (n, 4)) * 0.04 + rng.uniform(-0.01, 0.01, (n, 4))
    truth[:, 1:, 3] = rng.uniform(-0.3, 0.1, (n, 4))
    seen = truth.copy()
    seen[:, 1:, 1:] += rng.uniform(-eps, eps, (n, 4, 4)).astype(np.float32)
    plain, robust = ObservationRules(preset), ObservationRules(preset, eps)
    np.testing.assert_array_equal(ObservationRules(preset, 0.0).actions(seen), plain.actions(seen))
    fast = robust.actions(seen) == FASTER
    assert 50 < fast.sum() < n / 2                                      # not vacuous, not reckless
    assert np.isin(plain.actions(truth)[fast], [FASTER, LANE_RIGHT]).all()
    assert (plain.actions(seen) == FASTER).sum() > fast.sum()           # the plain rules dare more


def test_robust_rules_are_a_named_budgeted_baseline() -> None:
    from zodrive.drivers.baselines import get_baseline
    from zodrive.errors import ZodriveError

    assert get_baseline("baseline:robust-rules").eps == 0.05
    assert get_baseline("baseline:robust-rules@0.02").eps == 0.02
    for bad in ("baseline:robust-rules@x", "baseline:rules@0.1", "baseline:robust-rules@2"):
        with pytest.raises(ZodriveError, match="@EPS"):
            get_baseline(bad)
    victim = load_victim("baseline:robust-rules@0.02", load_preset("discrete"))
    assert victim.reads == "observation" and victim.differentiable is None


def test_close_rules_follow_closer_and_otherwise_decide_as_the_rules() -> None:
    """`baseline:close-rules` is the rules with IDM's time gap 0.3 s and a 5 m margin: a car 40 m
    ahead at the same speed leaves room to speed up for them (10 + 25 * 0.3 + 5 < 35 m) and not for
    the rules (10 + 25 * 1.0 + 15 > 35 m); far from any car, or close behind one, both decide alike."""
    from zodrive.drivers.rules import FASTER, IDLE, ObservationRules

    preset = load_preset("discrete")
    alone = np.zeros((1, 5, 5), np.float32)
    alone[0, 0] = [1, 1, 0.12, 1, 0]  # the right lane, >= 20 m/s
    ahead = alone.copy()
    ahead[0, 1] = [1, 0.4, 0, 0, 0]  # a car 40 m ahead (35 m gap), same speed
    close_car = alone.copy()
    close_car[0, 1] = [1, 0.12, 0, -0.1, 0]  # 12 m ahead, 2 m/s slower
    batch = np.concatenate([alone, ahead, close_car])
    plain = load_victim("baseline:rules", preset)
    close = load_victim("baseline:close-rules", preset)
    assert plain.actions(plain.query(batch)).tolist()[:2] == [FASTER, IDLE]
    assert close.actions(close.query(batch)).tolist()[:2] == [FASTER, FASTER]
    assert close.actions(close.query(batch))[2] == plain.actions(plain.query(batch))[2]
    assert close.reads == "observation" and close.differentiable is None
    np.testing.assert_array_equal(ObservationRules(preset).actions(batch), plain.actions(plain.query(batch)))


def test_brake_escape_brakes_and_leaves_its_lane_only_where_braking_cannot_keep_the_gap() -> None:
    """`baseline:brake-escape` on merge: SLOWER on a free road and behind a car it can follow, a
    lane change towards a free lane where a car ahead is closer than braking to 20 m/s can hold.
    On merge's two-lane main road (the on-ramp is not a lane to escape to) the right lane is lane 1."""
    from zodrive.drivers.rules import LANE_LEFT, SLOWER
    from zodrive.envs import scenario

    preset = load_preset("merge")
    assert scenario(preset).lanes == 2 and scenario(load_preset("highway-fast")).lanes == 3
    x, y, v = (scenario(preset).feature_ranges[k][1] for k in ("x", "y", "vx"))
    alone = np.zeros((1, 5, 5), np.float32)
    alone[0, 0] = [1, 100 / x, 4 / y, 20 / v, 0]  # the right lane at 20 m/s
    far = alone.copy()
    far[0, 1] = [1, 80 / x, 0, 0, 0]  # a car 80 m ahead at the same speed
    close_car = alone.copy()
    close_car[0, 1] = [1, 12 / x, 0, -3 / v, 0]  # 12 m ahead, 3 m/s slower: braking to 20 m/s cannot keep the gap
    boxed_in = close_car.copy()
    boxed_in[0, 2] = [1, 2 / x, -4 / y, 0, 0]  # and a car beside it in the left lane
    driver = load_victim("baseline:brake-escape", preset)
    actions = driver.actions(driver.query(np.concatenate([alone, far, close_car, boxed_in]))).tolist()
    assert actions == [SLOWER, SLOWER, LANE_LEFT, SLOWER]
    assert driver.reads == "observation" and driver.differentiable is None


@pytest.mark.parametrize("baseline, crashed", [("baseline:slower", True), ("baseline:brake-escape", False)])
def test_on_merge_the_brake_rear_ends_a_car_that_merged_in_and_brake_escape_does_not(baseline: str,
                                                                                 crashed: bool) -> None:
    """Seed 50032 (a tuning seed): a car merges in ahead slower than 20 m/s; the constant brake
    cannot slow below that and hits it, brake-escape changes lanes."""
    import zodrive

    episode = zodrive.evaluate(baseline, "merge", episodes=1, seed=50032).episodes[0]
    assert episode["crashed"] is crashed


def test_a_score_attack_on_a_decision_only_policy_says_what_its_rows_mean(caplog) -> None:
    """baseline:rules answers one-hot: ZO-SignSGD got identical rows at every eps with no word of why."""
    import logging

    import zodrive

    with caplog.at_level(logging.WARNING, logger="zodrive"):
        zodrive.attack("baseline:rules", np.zeros((1, 5, 5), dtype=np.float32), "highway-fast", "zo-signsgd",
                       eps=0.05, steps=2)
    assert "answers with its decision alone" in caplog.text and "lower bound" in caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="zodrive"):
        zodrive.attack("baseline:rules", np.zeros((1, 5, 5), dtype=np.float32), "highway-fast", "random-search",
                       eps=0.05, steps=2)
    assert "decision alone" not in caplog.text  # random search needs only decisions
