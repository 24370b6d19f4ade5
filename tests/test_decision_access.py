"""Decision-only access (`access: decision`) and the decision-based attack (`hsja`, attacks/boundary.py).

With decision access the oracle, the one place queries are made, returns only the one-hot vector of
the action taken: no query, no gradient and no attribute of the oracle gives an attack the scores,
while every row sent to the victim is still counted. Attacks that need scores are refused in one line.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from toys import context, linear_victim, observations
from zodrive.attacks import ATTACKS, AttackSpec
from zodrive.attacks.oracle import QueryOracle
from zodrive.attacks.spec import decision_attacks
from zodrive.attacks.victim import Victim
from zodrive.errors import ZodriveError

ROOT = Path(__file__).resolve().parents[1]
DECISION_SEARCHES = ["hsja", "random-search", "uniform-noise"]


def logging_victim(victim: Victim, log: list[tuple[np.ndarray, np.ndarray]]) -> Victim:
    """`victim` that logs every batch it is asked about with the scores it answered (calibration apart)."""

    def query(x: np.ndarray) -> np.ndarray:
        out = np.asarray(victim.query(x))
        log.append((np.array(x, copy=True), out.copy()))
        return out

    return Victim(query=query, kind=victim.kind, obs_shape=victim.obs_shape, differentiable=victim.differentiable,
                  calibrate=victim.calibrate)


@pytest.fixture
def attacker_view(monkeypatch: pytest.MonkeyPatch) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Every (batch, owners, outputs) the oracle hands to an attack."""
    seen: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    call = QueryOracle.__call__

    def spy(self: QueryOracle, batch: np.ndarray, owners: np.ndarray | None = None) -> np.ndarray:
        out = call(self, batch, owners)
        seen.append((np.array(batch, copy=True), np.arange(len(batch)) if owners is None else np.array(owners), out))
        return out

    monkeypatch.setattr(QueryOracle, "__call__", spy)
    return seen


def _one_hot(out: np.ndarray) -> bool:
    return bool(set(np.unique(out)) <= {0.0, 1.0} and np.all(out.sum(axis=-1) == 1))


def _build(name: str, victim: Victim, **options):
    return AttackSpec(attack=name, **options).build(victim, **context(victim.kind))


@pytest.mark.parametrize("name", DECISION_SEARCHES)
def test_the_attack_never_receives_scores_and_every_row_is_counted(name: str, attacker_view) -> None:
    log: list[tuple[np.ndarray, np.ndarray]] = []
    x0 = observations(6, seed=3)
    steps = {} if name == "uniform-noise" else {"steps": 12, "n_directions": 5, "early_stop": False}
    attack, objective, oracle = _build(name, logging_victim(linear_victim(seed=2), log), eps=0.3, access="decision",
                                       **steps)
    result = attack.perturb(x0, oracle, objective)
    raw = np.concatenate([out for _, out in log])
    assert not _one_hot(raw)  # the victim answered scores ...
    view = np.concatenate([out for _, _, out in attacker_view])
    assert _one_hot(view) and _one_hot(result.adv_outputs) and _one_hot(result.clean_outputs)  # ... the attack saw decisions
    np.testing.assert_array_equal(view.argmax(axis=1), raw.argmax(axis=1))  # the decisions the victim took
    sent = sum(len(batch) for batch, _ in log)
    assert sent == len(view) == oracle.total_queries == oracle.step_queries == result.queries.sum() > 6
    # no other door to the scores: the oracle's victim answers decisions and offers neither gradient nor network
    assert _one_hot(oracle.victim.query(x0)) and oracle.victim.differentiable is None and oracle.victim.calibrate is None
    with pytest.raises(ZodriveError, match="decision access gives no gradients"):
        oracle.gradient(x0, lambda out: out.sum(axis=1))


@pytest.mark.parametrize("name", DECISION_SEARCHES)
@pytest.mark.parametrize("norm,eps", [("linf", 0.1), ("l2", 0.3)])
def test_every_point_the_victim_receives_is_inside_the_ball_and_the_box_with_presence_unchanged(
        name: str, norm: str, eps: float, attacker_view) -> None:
    x0 = observations(3, seed=7)
    x0[:, 1:, 1] = 0.999  # clean values at the edge of the box: probes, lines and jumps must not leave it
    steps = {} if name == "uniform-noise" else {"steps": 25, "n_directions": 6, "early_stop": False}
    attack, objective, oracle = _build(name, linear_victim(seed=2), eps=eps, norm=norm, access="decision", **steps)
    for _ in range(2):  # two environment steps (the second one from the carried state, if any)
        attack.perturb(x0, oracle, objective)
    points = np.concatenate([batch for batch, _, _ in attacker_view]).reshape(-1, 5, 5)
    owners = np.concatenate([owners for _, owners, _ in attacker_view])
    delta = (points - x0[owners]).reshape(len(points), -1)
    size = np.abs(delta).max(axis=1) if norm == "linf" else np.linalg.norm(delta, axis=1)
    assert size.max() <= eps + 1e-5
    assert points.min() >= -1 and points.max() <= 1
    np.testing.assert_array_equal(points[:, :, 0], x0[owners][:, :, 0])


@pytest.mark.parametrize("name", sorted(set(ATTACKS) - set(decision_attacks())) + ["learned"])
def test_an_attack_that_needs_scores_is_refused_in_one_line(name: str) -> None:
    with pytest.raises(ZodriveError) as refused:
        AttackSpec(attack=name, access="decision").check()
    assert "\n" not in str(refused.value) and f"attack {name} does not run with access decision" in str(refused.value)
    assert {"zo-signsgd", "nes", "spsa", "zo-sgd", "coordinate-fd", "fgsm", "pgd"} <= set(ATTACKS) - set(decision_attacks())


def test_decision_access_on_a_continuous_victim_is_refused_it_changes_nothing() -> None:
    with pytest.raises(ZodriveError, match="changes nothing for a continuous victim"):
        _build("hsja", linear_victim(kind="continuous"), access="decision")


def test_the_command_line_refuses_in_one_line_and_reads_the_flag(capsys) -> None:
    from zodrive.cli import build_parser, main
    from zodrive.cli.attack import attack_spec_from_args

    code = main(["evaluate", "baseline:rules", "--attack", "zo-signsgd", "--access", "decision", "--episodes", "1"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "does not run with access decision" in err
    args = build_parser().parse_args(["evaluate", "baseline:rules", "--attack", "hsja", "--access", "decision"])
    spec = attack_spec_from_args(args)
    assert (spec.attack, spec.access) == ("hsja", "decision") and spec.to_dict()["access"] == "decision"


@pytest.mark.parametrize("target", ["FASTER", "none"])
def test_hsja_succeeds_where_success_is_possible_and_every_success_is_the_victim_s(target: str) -> None:
    victim = linear_victim(seed=2)
    x0 = observations(48, seed=5)
    attack, objective, oracle = _build("hsja", victim, eps=0.5, steps=30, target=target, access="decision")
    result = attack.perturb(x0, oracle, objective)
    tried = ~result.already
    assert tried.sum() > 20 and result.success[tried].mean() > 0.5
    taken, clean = victim.query(result.x_adv).argmax(axis=1), victim.query(x0).argmax(axis=1)
    if target == "FASTER":
        np.testing.assert_array_equal(taken[result.success], 3)
    else:
        assert np.all(taken[result.success] != clean[result.success])
    np.testing.assert_array_equal(result.adv_outputs.argmax(axis=1), taken)  # what it reports is what the victim does


def _attack(name: str, victim: Victim, x0: np.ndarray, **options):
    attack, objective, oracle = _build(name, victim, **options)
    return attack.perturb(x0, oracle, objective)


def test_the_boundary_phase_shrinks_the_distance_of_a_success_inside_the_ball() -> None:
    victim = linear_victim(seed=2)
    x0 = observations(48, seed=5)
    first = _attack("hsja", victim, x0, eps=0.5, steps=40, access="decision")
    walked = _attack("hsja", victim, x0, eps=0.5, steps=40, access="decision", early_stop=False)
    both = first.success & walked.success
    assert both.sum() > 20
    assert np.all(walked.linf[both] <= first.linf[both] + 1e-6)
    assert walked.linf[both].mean() < 0.8 * first.linf[both].mean()
    np.testing.assert_array_equal(victim.query(walked.x_adv).argmax(axis=1)[walked.success], 3)


def test_hsja_reads_only_the_decision() -> None:
    """Its search follows the goal's indicator alone: with scores or decisions it queries the same points and
    succeeds on the same rows (only the miss it feeds may differ: misses are ranked by the objective)."""
    victim = linear_victim(seed=2)
    x0 = observations(24, seed=8)
    runs = []
    for access in ("score", "decision"):
        attack, objective, oracle = _build("hsja", victim, eps=0.2, steps=15, n_directions=6, access=access,
                                           early_stop=False)
        runs.append(attack.perturb(x0, oracle, objective))
    score, decision = runs
    np.testing.assert_array_equal(score.success, decision.success)
    np.testing.assert_array_equal(score.queries, decision.queries)
    np.testing.assert_array_equal(score.x_adv[score.success], decision.x_adv[decision.success])
    assert 0 < score.success.sum() < len(x0)


def test_same_seed_same_result_and_rows_in_lockstep_are_one_row_runs() -> None:
    victim = dataclasses.replace(linear_victim(seed=2), calibrate=None)  # rows never mixed: one-row calls
    x0 = observations(5, seed=4)

    def run(rows: np.ndarray, base: int):
        """Two consecutive environment steps of `rows`, row r's stream seeded base + r."""
        attack, objective, oracle = _build("hsja", victim, eps=0.5, steps=10, n_directions=4, access="decision",
                                           early_stop=False)
        attack.reseed([base + int(r) for r in rows])
        return [attack.perturb(x0[rows] + np.float32(0.01 * t), oracle, objective) for t in range(2)]

    a, b = run(np.arange(5), 100), run(np.arange(5), 100)
    assert 0 < a[0].success.sum() < 5  # rows that walk the boundary and rows that search to the end
    for ra, rb in zip(a, b):
        for field in ("x_adv", "success", "queries", "iterations", "linf"):
            np.testing.assert_array_equal(getattr(ra, field), getattr(rb, field))
    alone = [run(np.array([r]), 100) for r in range(5)]
    for t in range(2):
        np.testing.assert_array_equal(a[t].x_adv, np.concatenate([one[t].x_adv for one in alone]))
        np.testing.assert_array_equal(a[t].queries, np.concatenate([one[t].queries for one in alone]))
    assert not np.array_equal(run(np.arange(5), 200)[0].x_adv, a[0].x_adv)  # another seed, another attack


def test_score_access_is_recorded_as_before_and_a_record_with_decision_access_resumes() -> None:
    """An evaluation key made before `access` came back (it records none) is one with score access; one made while
    it existed first (c645e5d's parent recorded `access`) reads back as it was."""
    from zodrive.evaluation.evaluate import same_evaluation

    today = AttackSpec(attack="random-search").to_dict()
    old = {k: v for k, v in today.items() if k != "access"}
    assert same_evaluation({"attack": old}, {"attack": today})
    assert not same_evaluation({"attack": old}, {"attack": {**today, "access": "decision"}})
    assert AttackSpec.from_mapping({**old, "access": "decision"}).access == "decision"


def test_on_decisions_hsja_s_independent_vertices_find_more_than_random_search_s_local_moves() -> None:
    """Before its first success a decision-based search has a flat objective: random search then re-draws a few
    coordinates of one failing vertex, hsja draws whole fresh vertices. Same budget, same toy, more successes."""
    victim = linear_victim(seed=4)
    x0 = observations(100, seed=11)
    found = {name: _attack(name, victim, x0, eps=0.2, steps=30, n_directions=10, access="decision")
             for name in ("hsja", "random-search")}
    tried = ~found["hsja"].already
    rate = {name: result.success[tried].mean() for name, result in found.items()}
    assert rate["hsja"] > rate["random-search"] + 0.05, rate
    assert found["hsja"].queries.max() <= 2 + 30 * 10
