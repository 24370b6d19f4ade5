"""Attack engine: estimators, budgets, determinism, query counting, bad parameters."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from toys import CONTEXT, context, counting_victim, linear_victim, observations, readable
from zodrive.attacks.victim import Victim
from zodrive.attacks import ATTACKS, AttackSpec, ThreatModel, make_attack
from zodrive.attacks.base import GradientEstimateAttack
from zodrive.attacks.oracle import PROBE_SIZES, stable_batch
from zodrive.errors import ZodriveError

ESTIMATORS = [name for name, cls in ATTACKS.items() if issubclass(cls, GradientEstimateAttack)]

SEARCHES = [name for name, cls in ATTACKS.items() if cls.search]  # vertex hold: tests/test_hold.py


@pytest.mark.parametrize("name", ESTIMATORS)
def test_estimator_points_along_the_true_gradient(name: str) -> None:
    """On f(x) = 0.5 x^T H x + b^T x the estimate's direction matches H x + b."""
    d = 25
    rng = np.random.default_rng(0)
    m = rng.standard_normal((d, d))
    hess, b = m @ m.T / d, rng.standard_normal(d)
    x = rng.standard_normal(d)
    threat = ThreatModel(frozen=())
    attack = make_attack(name, threat, n_directions=4000, mu=1e-3, seed=0)
    mask = np.ones(d)
    u = attack.directions(np.arange(1), d, mask)
    f = lambda z: 0.5 * np.einsum("...i,ij,...j->...", z, hess, z) + z @ b  # noqa: E731
    points = [x[None, None]] + [x + s * attack.mu * u for s in ((1, -1) if attack.antithetic else (1,))]
    values = f(np.concatenate(points, axis=1))
    g = attack.estimate(values, u, d)[0]
    true = hess @ x + b
    cosine = g @ true / (np.linalg.norm(g) * np.linalg.norm(true))
    assert cosine > 0.9, cosine
    if name in ("zo-sgd", "nes", "spsa", "coordinate-fd"):  # unbiased: the scale is right too
        assert np.linalg.norm(g) / np.linalg.norm(true) == pytest.approx(1.0, rel=0.25)


def _run(name: str, victim: Victim, x0: np.ndarray, seed: int = 0, **kw):
    """Run attack `name`; options it does not read (`Attack.reads`: uniform noise takes no steps) are dropped."""
    spec = AttackSpec(attack=name, seed=seed, **readable(name, **kw))
    attack, objective, oracle = spec.build(victim, **context(victim.kind))
    return attack.perturb(x0, oracle, objective), oracle, attack


@pytest.mark.parametrize("name", SEARCHES)
@pytest.mark.parametrize("norm", ["linf", "l2"])
def test_every_attack_stays_in_budget_and_keeps_presence(name: str, norm: str) -> None:
    x0 = observations(16)
    eps = 0.2 if norm == "linf" else 0.5
    result, _, _ = _run(name, linear_victim(), x0, eps=eps, norm=norm, steps=20)
    delta = (result.x_adv - x0).reshape(16, -1)
    size = np.abs(delta).max(axis=1) if norm == "linf" else np.linalg.norm(delta, axis=1)
    assert size.max() <= eps + 1e-5
    np.testing.assert_array_equal(result.x_adv[:, :, 0], x0[:, :, 0])
    assert result.x_adv.min() >= -1 and result.x_adv.max() <= 1


@pytest.mark.parametrize("name", SEARCHES)
def test_every_attack_is_deterministic_given_a_seed(name: str) -> None:
    x0 = observations(8)
    a, _, _ = _run(name, linear_victim(), x0, seed=3, steps=15)
    b, _, _ = _run(name, linear_victim(), x0, seed=3, steps=15)
    np.testing.assert_array_equal(a.x_adv, b.x_adv)
    np.testing.assert_array_equal(a.queries, b.queries)


@pytest.mark.parametrize("name", [n for n in SEARCHES if n != "uniform-noise"])
@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_every_attack_beats_the_noise_floor(name: str, kind: str) -> None:
    victim = linear_victim(seed=2, kind=kind)
    x0 = observations(64, seed=5)
    noise, _, _ = _run("uniform-noise", victim, x0, eps=0.5)
    result, _, _ = _run(name, victim, x0, steps=60, eps=0.5)
    applicable = ~result.already
    assert applicable.sum() > 10
    margin = 0.0 if name == "fgsm" else 0.15  # one linearized step: only required to not lose
    assert result.success[applicable].mean() > noise.success[applicable].mean() + margin


@pytest.mark.parametrize("target", ["none", "FASTER"])
def test_untargeted_and_targeted_objectives(target: str) -> None:
    victim = linear_victim(seed=4)
    x0 = observations(32)
    result, _, _ = _run("zo-signsgd", victim, x0, target=target, eps=0.4)
    clean_action = victim.query(x0).argmax(1)
    adv_action = victim.query(result.x_adv).argmax(1)
    hit = result.success
    if target == "none":
        assert np.all(adv_action[hit] != clean_action[hit])
    else:
        assert np.all(adv_action[hit] == 3)
    assert hit.mean() > 0.3


@pytest.mark.parametrize("name", ["zo-signsgd", "random-search", "pgd"])
def test_an_avoid_target_keeps_the_victim_off_that_action_and_never_reads_the_clean_output(name: str) -> None:
    victim = linear_victim(seed=4)
    x0 = observations(64)
    avoid = int(np.bincount(victim.query(x0).argmax(1), minlength=5).argmax())  # the toy's most frequent action
    spec = AttackSpec(attack=name, target=f"not:{avoid}", eps=0.4, steps=30)
    attack, objective, oracle = spec.build(victim, **context("discrete"))
    assert not objective.reads_clean and objective.loss(torch.zeros(1, 1, 5), torch.full((1, 5), float("nan"))).isfinite().all()
    result = attack.perturb(x0, oracle, objective)
    adv_action = victim.query(result.x_adv).argmax(1)
    clean_avoid = victim.query(x0).argmax(1) == avoid
    np.testing.assert_array_equal(result.already, ~clean_avoid)  # nothing to do where it already avoids it
    np.testing.assert_array_equal(result.success[clean_avoid], adv_action[clean_avoid] != avoid)
    assert result.success[clean_avoid].mean() > 0.5  # it moved most of those off the avoided action
    named = AttackSpec(attack=name, target="not:FASTER").build(victim, **context("discrete"))[1]
    assert named.avoid == 3


@pytest.mark.parametrize("name", ["random-search", "pgd"])
def test_a_fallback_target_keeps_the_victim_off_an_action_where_the_target_is_out_of_reach(name: str) -> None:
    """`--target T,not:A`: success is still T; where T is not reached, the fed point's action is A less often than
    with T alone; and the loss is T's margin loss plus A's avoid loss."""
    victim = linear_victim(seed=4)
    x0 = observations(64)
    counts = np.bincount(victim.query(x0).argmax(1), minlength=5)
    avoid, target = int(counts.argmax()), int(np.argsort(counts)[1])  # the most frequent action; a rare one
    fed_avoided = {}
    for goal in (f"{target}", f"{target},not:{avoid}"):
        attack, objective, oracle = AttackSpec(attack=name, target=goal, eps=0.05, steps=30).build(victim, **context("discrete"))
        result = attack.perturb(x0, oracle, objective)
        adv_action = victim.query(result.x_adv).argmax(1)
        np.testing.assert_array_equal(result.success | result.already, adv_action == target)
        missed = ~(result.success | result.already)
        assert missed.mean() > 0.5  # the target is mostly out of reach at this budget
        fed_avoided[goal] = float((adv_action[missed] == avoid).mean())
    assert fed_avoided[f"{target},not:{avoid}"] < fed_avoided[f"{target}"], fed_avoided
    q = torch.randn(8, 3, 5)
    both = AttackSpec(target="FASTER,not:SLOWER").build(victim, **context("discrete"))[1]
    alone = AttackSpec(target="FASTER").build(victim, **context("discrete"))[1]
    off = AttackSpec(target="not:SLOWER").build(victim, **context("discrete"))[1]
    assert (both.target, both.avoid) == (3, 4) and not both.reads_clean
    torch.testing.assert_close(both.loss(q, q[:, 0]), alone.loss(q, q[:, 0]) + off.loss(q, q[:, 0]))
    torch.testing.assert_close(both.success(q, q[:, 0]), alone.success(q, q[:, 0]))


@pytest.mark.parametrize("target, message", [("FASTER,SLOWER", "ACTION,not:ACTION"), ("not:IDLE,not:SLOWER", "ACTION,not:ACTION"),
                                             ("FASTER,not:SLOWER,not:IDLE", "ACTION,not:ACTION"),
                                             ("FASTER,not:FASTER", "avoids the action it aims at"),
                                             ("FASTER,not:FLY", "unknown target 'FASTER,not:FLY'")])
def test_a_bad_fallback_target_is_a_one_line_error(target: str, message: str) -> None:
    with pytest.raises(ZodriveError, match=message):
        AttackSpec(attack="random-search", target=target).build(linear_victim(), **context("discrete"))
    with pytest.raises(ZodriveError, match="only the margin loss"):
        AttackSpec(attack="zo-signsgd", target="FASTER,not:SLOWER", loss="paper").build(linear_victim(), **context("discrete"))


@pytest.mark.parametrize("target, message", [("not:FLY", "unknown target 'not:FLY'"), ("not:7", r"7 \('not:7'\) is out of range 0..4"),
                                             ("not:", "unknown target 'not:'")])
def test_a_bad_avoid_target_is_a_one_line_error(target: str, message: str) -> None:
    with pytest.raises(ZodriveError, match=message):
        AttackSpec(attack="zo-signsgd", target=target).build(linear_victim(), **context("discrete"))
    with pytest.raises(ZodriveError, match="acts continuously"):
        AttackSpec(attack="zo-signsgd", target="not:FASTER").build(linear_victim(kind="continuous"),
                                                                   **context("continuous"))
    with pytest.raises(ZodriveError, match="only the margin loss"):
        AttackSpec(attack="zo-signsgd", target="not:SLOWER", loss="paper").build(linear_victim(), **context("discrete"))


def test_oracle_counts_every_query_exactly() -> None:
    calls: list[int] = []
    victim = counting_victim(calls)
    x0 = observations(4)
    result, oracle, attack = _run("zo-signsgd", victim, x0, steps=10, n_directions=7, early_stop=False)
    assert oracle.step_queries == sum(calls)  # the calibration goes to the harness's own copy, not the victim
    assert oracle.step_queries == result.queries.sum()
    assert oracle.calls == 1 + 10  # clean batch, then one call per iteration
    # iteration 0's base point is the clean observation: queried once, not twice
    assert result.queries.max() == attack.queries_per_step() == 10 * 8


def test_query_budget_stops_the_attack() -> None:
    x0 = observations(3)
    result, oracle, _ = _run("zo-signsgd", linear_victim(), x0, steps=100, n_directions=9,
                             early_stop=False, query_budget=50)
    assert oracle.step_queries <= 3 * 50
    assert result.queries.max() <= 50


def test_plain_numpy_function_is_a_victim() -> None:
    w = np.random.default_rng(0).standard_normal((25, 5))
    victim = Victim(query=lambda x: x.reshape(len(x), -1) @ w, kind="discrete", obs_shape=(5, 5))
    result, _, _ = _run("nes", victim, observations(16), eps=0.3)
    assert result.success.any()


def test_white_box_attacks_refuse_a_black_box_victim() -> None:
    victim = Victim(query=linear_victim().query, kind="discrete", obs_shape=(5, 5))
    with pytest.raises(ZodriveError, match="white-box"):
        AttackSpec(attack="pgd").build(victim, **CONTEXT)


@pytest.mark.parametrize(
    "changes,message",
    [
        ({"eps": 0.0}, "eps"), ({"eps": -1.0}, "eps"), ({"steps": 0}, "steps"),
        ({"n_directions": 0}, "n_directions"), ({"attack": "nope"}, "unknown attack"),
        ({"target": "WARP"}, "unknown target"), ({"target": 7}, "out of range"),
        ({"mu": 0.0}, "mu"), ({"norm": "l1"}, "norm"), ({"query_budget": 0}, "query_budget"),
        ({"loss": "hinge"}, "loss"), ({"query_budget": 5}, "below one iteration of zo-signsgd \\(21 queries"),
        ({"attack": "random-search", "query_budget": 21}, "below one iteration"),
    ],
)
def test_bad_attack_parameters_give_one_clear_error(changes: dict, message: str) -> None:
    with pytest.raises(ZodriveError, match=message):
        AttackSpec(**changes).build(linear_victim(), **CONTEXT)


def test_paper_mode_is_unconstrained_but_clipped() -> None:
    x0 = observations(8)
    result, _, _ = _run("zo-signsgd", linear_victim(), x0, mode="paper", eps=0.05,
                        step_size=0.05, early_stop=False, l2_weight=0.0)
    assert result.linf.max() > 0.05
    assert result.x_adv.min() >= -1 and result.x_adv.max() <= 1


def test_vectorized_attack_sends_one_call_per_iteration_for_all_envs() -> None:
    """Batched across environments: one victim call per iteration whatever N is, once each
    row's share of it is a batch whose outputs no longer depend on the batch size; the clean
    query (one row each) goes row by row, as N one-row runs would send it."""
    calls: list[int] = []
    victim = counting_victim(calls)
    for n in (1, 6):
        calls.clear()
        result, oracle, _ = _run("zo-signsgd", victim, observations(n), steps=10, n_directions=15, early_stop=False)
        assert n == 1 or oracle.stable_batch <= 15  # the premise: a share of 15 or 16 rows is batched
        assert len(calls) == n + 10  # the calibration went to the harness's own copy: the victim saw none of it
        assert calls[:n + 2] == [1] * n + [n * 15, n * 16]  # iteration 0: probes only


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_rows_are_independent_of_each_other(kind: str) -> None:
    """N rows with their own seeds give what N one-row runs give, bit for bit, for every
    attack, with per-step budgets and the per-step state (warm start,
    max_change) carried over two steps: what lockstep evaluation rests on. The continuous
    victim's target is out of reach, so rows run until their budgets stop them, at
    different iterations (a row whose base point is known spends one query less)."""
    x0 = observations(5)
    later = np.clip(x0 + 0.01, -1, 1).astype(np.float32)  # the next step's observations
    for name in ["zo-signsgd", "zo-sgd", "nes", "spsa", "coordinate-fd", "random-search", "uniform-noise",
                 "pgd", "fgsm"]:
        options = dict(steps=6 if kind == "discrete" else 12, n_directions=5, warm_start=True, max_change=0.05,
                       query_budget=40, eps=0.1)
        spec = AttackSpec(attack=name, **readable(name, **options))
        together = spec.build(linear_victim(kind=kind), **context(kind))
        together[0].reseed([11, 12, 13, 14, 15])
        joint = [_step_of(together, x) for x in (x0, later)]
        for row in range(5):
            alone = spec.build(linear_victim(kind=kind), **context(kind))
            alone[0].reseed(11 + row)
            single = [_step_of(alone, x[row:row + 1]) for x in (x0, later)]
            for a, b in zip(joint, single):
                for field in ("x_adv", "success", "queries", "iterations"):
                    assert np.array_equal(getattr(a, field)[row], getattr(b, field)[0]), (name, row, field)


def test_a_row_out_of_budget_stops_while_the_others_go_on() -> None:
    """Rows spend their per-step budgets at different paces (a row where the victim ignores
    the observation never moves, so its base point is known and costs no query): when one
    cannot pay for an iteration, it stops and the others carry on with their own directions,
    each as its one-row run (this raised a shape error in the gradient estimate before)."""
    base = linear_victim(kind="continuous")

    def query(x: np.ndarray) -> np.ndarray:
        out = base.query(x)
        out[np.asarray(x)[:, 1, 1] > 0] = 0.5  # rows whose second vehicle is ahead: a flat policy
        return out

    victim = Victim(query=query, kind="continuous", obs_shape=(5, 5))
    x0 = observations(6)
    x0[:3, 1, 1], x0[3:, 1, 1] = 0.5, -0.5
    spec = AttackSpec(attack="zo-signsgd", steps=12, n_directions=5, query_budget=40, eps=0.1, target="1,1", tol=0.01)
    together = spec.build(victim, **context("continuous"))
    together[0].reseed(list(range(6)))
    joint = _step_of(together, x0)
    assert len(set(joint.iterations.tolist())) > 1  # the premise: rows stop at different iterations
    for row in range(6):
        alone = spec.build(victim, **context("continuous"))
        alone[0].reseed(row)
        single = _step_of(alone, x0[row:row + 1])
        for field in ("x_adv", "queries", "iterations"):
            assert np.array_equal(getattr(joint, field)[row], getattr(single, field)[0]), (row, field)


def test_rows_are_not_mixed_where_a_row_s_place_in_a_batch_changes_its_outputs() -> None:
    """A victim whose kernels round odd and even rows of a batch differently (as a matrix
    product over (in, out) weights does on this machine) passes a check of batch sizes alone;
    the oracle's calibration also moves the rows, finds it out and never mixes rows, so N
    rows still give what N one-row runs give."""
    base = linear_victim()

    def query(x: np.ndarray) -> np.ndarray:
        out = base.query(x)
        return out + np.float32(1e-3) * (np.arange(len(out)) % 2)[:, None].astype(np.float32)

    victim = Victim(query=query, kind="discrete", obs_shape=(5, 5))
    assert stable_batch(query, (5, 5))[0] > PROBE_SIZES[-1]
    x0 = observations(4)
    spec = AttackSpec(attack="zo-sgd", steps=5, n_directions=5, early_stop=False)
    together = spec.build(victim, **CONTEXT)
    together[0].reseed([1, 2, 3, 4])
    joint = _step_of(together, x0)
    for row in range(4):
        alone = spec.build(victim, **CONTEXT)
        alone[0].reseed(row + 1)
        assert np.array_equal(joint.x_adv[row], _step_of(alone, x0[row:row + 1]).x_adv[0]), row


def _step_of(built, x):
    attack, objective, oracle = built
    return attack.perturb(x, oracle, objective)


def test_an_eps_that_covers_the_whole_box_is_reported_and_one_past_it_refused(caplog) -> None:
    low, high = CONTEXT["bounds"]
    with caplog.at_level("WARNING"):
        AttackSpec(eps=high - low).build(linear_victim(), **CONTEXT)
    assert "covers the whole observation box" in caplog.text
    with pytest.raises(ZodriveError, match="more than any observation value can move"):  # it would record what
        AttackSpec(eps=1e6).build(linear_victim(), **CONTEXT)  # did not run (the schema's largest eps)


def test_an_unbounded_observation_box_is_reported(caplog) -> None:
    with caplog.at_level("WARNING"):
        AttackSpec(eps=0.1).build(linear_victim(), **{**CONTEXT, "bounds": (float("-inf"), float("inf"))})
    assert "the observation box is unbounded" in caplog.text
    caplog.clear()
    with caplog.at_level("WARNING"):
        AttackSpec(eps=0.1).build(linear_victim(), **CONTEXT)
    assert "unbounded" not in caplog.text
