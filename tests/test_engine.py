"""The attack driver: exact per-row accounting, every queried point realizable, honest results."""

from __future__ import annotations

import numpy as np
import pytest

from toys import CONTEXT, context, linear_victim, observations, readable
from zodrive.attacks import ATTACKS, AttackSpec, ThreatModel
from zodrive.attacks.victim import Victim
from zodrive.errors import ZodriveError

SEARCHES = [name for name, cls in ATTACKS.items() if cls.search]  # vertex hold: tests/test_hold.py


def recording(victim: Victim, seen: list[np.ndarray]) -> Victim:
    """`victim` that keeps every batch it is asked about (queries and white-box passes)."""

    def query(x: np.ndarray) -> np.ndarray:
        seen.append(np.array(x, copy=True))
        return victim.query(x)

    def forward(x):  # type: ignore[no-untyped-def]
        seen.append(x.detach().numpy().copy())
        return victim.differentiable(x)

    return Victim(query=query, kind=victim.kind, obs_shape=victim.obs_shape, differentiable=forward,
                  calibrate=victim.calibrate)  # the harness's calibration goes to its own copy, not recorded


def _attack(name: str, victim: Victim, x0: np.ndarray, **kw):
    attack, objective, oracle = AttackSpec(attack=name, **readable(name, **kw)).build(victim, **context(victim.kind))
    return attack.perturb(x0, oracle, objective), oracle, attack


@pytest.mark.parametrize("name", SEARCHES)
@pytest.mark.parametrize("early_stop", [True, False])
def test_every_query_is_counted_once_per_row(name: str, early_stop: bool) -> None:
    seen: list[np.ndarray] = []
    x0 = observations(6)
    result, oracle, attack = _attack(name, recording(linear_victim(), seen), x0, steps=8, n_directions=5,
                                     early_stop=early_stop)
    sent = sum(len(batch) for batch in seen)
    assert sent == oracle.step_queries == result.queries.sum() == oracle.total_queries  # calibration never reaches it
    assert np.array_equal(result.queries, oracle.row_queries)
    assert result.queries.max() <= attack.queries_per_step()
    if not early_stop:  # nothing stops a row; only a base point already queried is not asked again
        assert np.all(result.iterations == attack.steps)
        assert np.all(result.queries >= attack.queries_per_step() - attack.steps)


@pytest.mark.parametrize("name", [n for n in SEARCHES if n not in ("uniform-noise", "fgsm")])  # iterative ones
def test_budget_is_per_row_even_when_other_rows_finish_early(name: str) -> None:
    """Rows that need no attack (already at the target) must not hand their allowance to
    the rows still trying: before the fix, 32 rows with budget 200 let five rows spend 1,001."""
    victim = linear_victim(seed=4)
    pool = observations(400, seed=3)
    at_target = victim.query(pool).argmax(axis=1) == 3
    x0 = np.concatenate([pool[at_target][:12], pool[~at_target][:12]])
    budget = 60
    result, _, _ = _attack(name, victim, x0, steps=100, n_directions=9, query_budget=budget, eps=0.01)
    assert result.already[:12].all() and not result.already[12:].any()
    assert result.queries.max() <= budget
    assert np.all(result.queries[:12] == 1)  # the clean query only
    trying = ~result.success[12:]
    assert trying.sum() >= 6
    if ATTACKS[name].black_box:  # (PGD's sign step reaches a fixed point it need not query again)
        assert np.all(result.queries[12:][trying] > budget - 20)  # each used its own allowance


@pytest.mark.parametrize("name", SEARCHES)
@pytest.mark.parametrize("mode", ["budgeted", "paper"])
def test_every_queried_point_is_inside_the_box_and_the_ball(name: str, mode: str) -> None:
    seen: list[np.ndarray] = []
    x0 = observations(1, seed=7)
    x0[0, 1:, 1] = 0.999  # clean values at the edge of the box: probes must not leave it
    eps = 0.1
    _attack(name, recording(linear_victim(), seen), x0, steps=20, n_directions=6, eps=eps, mode=mode,
            early_stop=False, mu=0.05)
    points = np.concatenate([b.reshape(-1, 5, 5) for b in seen])
    assert points.min() >= -1 and points.max() <= 1
    np.testing.assert_array_equal(points[:, :, 0], np.broadcast_to(x0[:, :, 0], points[:, :, 0].shape))
    if mode == "budgeted":
        assert np.abs(points - x0).max() <= eps + 1e-6


@pytest.mark.parametrize("name", SEARCHES)
def test_adv_outputs_are_what_the_victim_says_on_x_adv(name: str) -> None:
    victim = linear_victim(seed=1)
    x0 = observations(12)
    result, _, _ = _attack(name, victim, x0, steps=10, n_directions=5)
    np.testing.assert_allclose(result.adv_outputs, victim.query(result.x_adv), atol=1e-5)
    np.testing.assert_allclose(result.clean_outputs, victim.query(x0), atol=1e-6)


@pytest.mark.parametrize("name", [n for n in SEARCHES if n not in ("fgsm", "pgd")])
def test_different_seeds_give_different_attacks(name: str) -> None:
    x0 = observations(8)
    a, _, _ = _attack(name, linear_victim(), x0, seed=1, steps=10, n_directions=5, early_stop=False)
    b, _, _ = _attack(name, linear_victim(), x0, seed=2, steps=10, n_directions=5, early_stop=False)
    assert not np.array_equal(a.x_adv, b.x_adv)


def test_the_box_never_moves_a_clean_value() -> None:
    """With an unclipped preset, values outside [-1, 1] are real: the attack must not clip them."""
    x0 = observations(4)
    x0[:, 1:, 1] = 3.5
    for bounds in ((-1.0, 1.0), (float("-inf"), float("inf"))):
        spec = AttackSpec(attack="zo-signsgd", eps=0.2, steps=10)
        attack, objective, oracle = spec.build(linear_victim(), **{**CONTEXT, "bounds": bounds})
        result = attack.perturb(x0, oracle, objective)
        assert result.linf.max() <= 0.2 + 1e-6


def test_a_guarantee_that_cannot_hold_is_an_error() -> None:
    threat = ThreatModel(frozen=("presence",), features=("presence", "x", "y", "vx", "vy"))
    with pytest.raises(ZodriveError, match="cannot freeze presence"):
        threat.mask((5, 7))
    mask = threat.mask((5, 5))
    assert (mask[:, 0] == 0).all() and (mask[:, 1:] == 1).all()  # presence frozen, the rest writable
    assert (ThreatModel(frozen=()).mask((5, 7)) == 1).all()  # nothing frozen: any shape is fine, all writable


def test_bounds_come_from_the_preset() -> None:
    from zodrive.envs import attack_context, load_preset

    assert attack_context(load_preset("discrete"))["bounds"] == (-1.0, 1.0)
    loose = load_preset("discrete", ["highway.observation.clip=false"])
    assert attack_context(loose)["bounds"] == (float("-inf"), float("inf"))


def test_white_box_pgd_is_at_least_as_strong_as_zo_signsgd() -> None:
    """The same signed-step loop with the exact gradient: the ceiling holds by construction."""
    victim = linear_victim(seed=2)
    x0 = observations(64, seed=5)
    pgd, _, _ = _attack("pgd", victim, x0, steps=60, eps=0.2)
    zo, _, _ = _attack("zo-signsgd", victim, x0, steps=60, eps=0.2)
    assert pgd.success.sum() >= zo.success.sum()


def test_the_attack_flips_the_shipped_dqn_on_real_states() -> None:
    """20 real highway states (tuning seeds) and the shipped paper-budget DQN: ZO-SignSGD at
    eps 0.2 lowers its objective and makes the policy pick FASTER on most of them."""
    from zodrive.policies.resolve import load_victim
    from zodrive.envs import attack_context, load_preset, make_env
    from zodrive.seeds import TUNING_SEED

    preset = load_preset("discrete")
    victim = load_victim("models/dqn", preset)
    env, states = make_env(preset), []
    for episode in range(4):
        obs, _ = env.reset(seed=TUNING_SEED + episode)
        for _ in range(5):
            states.append(obs)
            obs, *_ = env.step(int(victim.actions(victim.query(obs[None]))[0]))
    x0 = np.stack(states)
    attack, objective, oracle = AttackSpec(attack="zo-signsgd", eps=0.2).build(victim, **attack_context(preset))
    result = attack.perturb(x0, oracle, objective, trace=True)
    todo = ~result.already
    assert todo.sum() >= 15
    assert result.success[todo].mean() >= 0.6
    first, last = result.trace[0]["l1"][todo], np.nanmin([t["l1"][todo] for t in result.trace], axis=0)
    assert np.all(last <= first) and last.mean() < first.mean()
    assert np.all(victim.actions(victim.query(result.x_adv))[result.success] == 3)


def test_step_rates_are_resampled_by_episode() -> None:
    """Correlated steps: an episode-level bootstrap is wider than a Wilson CI over steps."""
    from zodrive.evaluation.stats import rate_ci, ratio_ci

    rng = np.random.default_rng(0)
    applicable = rng.integers(300, 450, 30)
    successes = (applicable * rng.uniform(0, 1, 30)).astype(int)  # each episode its own rate
    low, high = ratio_ci(successes, applicable)
    w_low, w_high = rate_ci(int(successes.sum()), int(applicable.sum()))
    assert low < successes.sum() / applicable.sum() < high
    assert high - low > 3 * (w_high - w_low)


def test_warm_start_begins_where_the_last_step_ended_and_forgets_at_a_new_episode() -> None:
    victim = linear_victim(seed=2)
    x0 = observations(16, seed=5)
    attack, objective, oracle = AttackSpec(attack="zo-signsgd", warm_start=True, eps=0.3).build(victim, **CONTEXT)
    first = attack.perturb(x0, oracle, objective)
    again = attack.perturb(x0, oracle, objective)  # the same observation: the carried point already succeeds
    won = first.success
    assert won.sum() >= 4
    assert np.all(again.iterations[won] == 1) and again.queries[won].sum() < first.queries[won].sum()
    attack.reseed(0)  # what the wrapper does at a seeded reset: the same stream, and no carried perturbation
    fresh = attack.perturb(x0, oracle, objective)
    np.testing.assert_array_equal(fresh.queries, first.queries)


def test_patience_gives_up_a_step_that_stopped_improving() -> None:
    victim = linear_victim(seed=2)
    x0 = observations(32, seed=5)
    slow, _, _ = _attack("zo-signsgd", victim, x0, eps=0.02, steps=100)
    quick, _, _ = _attack("zo-signsgd", victim, x0, eps=0.02, steps=100, patience=5)
    failed = ~slow.success & ~slow.already
    assert failed.sum() >= 5
    assert quick.queries[failed].mean() < 0.5 * slow.queries[failed].mean()


def test_worst_action_target_aims_at_what_the_victim_values_least() -> None:
    victim = linear_victim(seed=3)
    x0 = observations(32, seed=6)
    result, _, _ = _attack("zo-signsgd", victim, x0, target="worst", eps=0.5)
    worst = victim.query(x0).argmin(axis=1)
    taken = victim.query(result.x_adv).argmax(axis=1)
    assert result.success.sum() >= 5
    np.testing.assert_array_equal(taken[result.success], worst[result.success])
    with pytest.raises(ZodriveError, match="worst"):
        AttackSpec(target="worst").build(linear_victim(kind="continuous"), **context("continuous"))


@pytest.mark.parametrize("name", ["zo-signsgd", "random-search", "pgd", "uniform-noise"])
def test_max_change_keeps_every_fed_perturbation_within_reach_of_the_last(name: str) -> None:
    victim = linear_victim(seed=2)
    attack, objective, oracle = AttackSpec(attack=name, **readable(name, eps=0.3, max_change=0.02, steps=10,
                                                                   n_directions=4)).build(victim, **CONTEXT)
    rng = np.random.default_rng(0)
    x0 = observations(8, seed=5)
    last = None
    for _ in range(6):  # a drifting scene: each clean observation moves a little
        x0 = np.clip(x0 + rng.uniform(-0.01, 0.01, x0.shape).astype(np.float32), -1, 1)
        x0[:, :, 0] = 1.0
        result = attack.perturb(x0, oracle, objective)
        delta = result.x_adv - x0
        assert np.abs(delta).max() <= 0.3 + 1e-6
        if last is not None:  # the previous perturbation, carried to the new observation, moved by <= 0.02
            assert np.abs(delta - last).max() <= 0.02 + 1e-6
        assert result.queries.max() <= attack.queries_per_step() + 1
        np.testing.assert_allclose(result.adv_outputs, victim.query(result.x_adv), atol=1e-5)
        last = delta
    assert np.abs(last).max() > 0.05  # it builds up beyond one step's change
    attack.begin_episode()  # a new episode: the first step is free again
    fresh = attack.perturb(x0, oracle, objective).x_adv - x0
    # neither held within max_change of the clean point nor of the last episode's perturbation (a step
    # held to either reaches 0.02 + float32 rounding, so a bound at 0.02 itself could not tell)
    assert np.abs(fresh).max() > 0.05 and np.abs(fresh - last).max() > 0.05


def test_max_change_is_an_linf_idea() -> None:
    with pytest.raises(ZodriveError, match="max_change"):
        AttackSpec(norm="l2", max_change=0.01).build(linear_victim(), **CONTEXT)
    with pytest.raises(ZodriveError, match="max_change"):
        AttackSpec(max_change=0.0).check()


@pytest.mark.parametrize("threat", [ThreatModel(eps=0.1), ThreatModel(eps=0.3, norm="l2"),
                                    ThreatModel(eps=0.1, mode="paper"), ThreatModel(eps=0.2, low=-0.5, high=0.5)])
def test_projecting_around_rows_is_projecting_each_candidate(threat: ThreatModel) -> None:
    """The engine projects (rows, candidates, dim) around each row's clean observation at once
    (`ThreatModel.around`); every candidate must land exactly where `project` puts it alone."""
    rng = np.random.default_rng(3)
    x0 = rng.uniform(-1, 1, size=(4, 5, 5)).astype(np.float32)
    x0[0, 0, 1] = 0.9  # a clean value outside the narrow box stays reachable
    cand = (x0.reshape(4, 1, 25) + rng.normal(0, 0.4, size=(4, 7, 25))).astype(np.float32)
    rows = np.array([2, 0, 3])
    got = threat.around(x0.reshape(4, 25), (5, 5))(cand[rows], rows)
    for i, r in enumerate(rows):
        for m in range(7):
            alone = threat.project(cand[r, m].reshape(1, 5, 5), x0[r:r + 1]).reshape(25)
            assert np.array_equal(got[i, m], alone)


@pytest.mark.parametrize("name", ["pgd", "fgsm"])
def test_white_box_attacks_leave_a_zero_gradient(name: str) -> None:
    """Untargeted on a continuous policy the objective (distance to the clean action) has a zero
    gradient at the clean point: a signed-gradient attack started there must still move."""
    x0 = observations(8)
    result, _, _ = _attack(name, linear_victim(kind="continuous"), x0, eps=0.2, target="none", tol=0.01, steps=20)
    assert result.linf.min() > 0 and result.success.mean() > 0.5


@pytest.mark.parametrize("name", ["random-search", "zo-signsgd", "uniform-noise", "nes"])
def test_integer_observations_are_attacked_with_integers_inside_the_ball(name: str) -> None:
    """Pixels (uint8): every queried point is whole, inside the eps-ball and [0, 255], and the fed
    observation is the queried one, not a wrapped or rounded copy (a float cast to uint8 wrapped -3 to 253)."""
    seen: list[np.ndarray] = []
    inner = linear_victim(seed=2)

    def query(x: np.ndarray) -> np.ndarray:
        seen.append(np.asarray(x, dtype=np.float64).copy())
        return inner.query(np.asarray(x, dtype=np.float32) / 255.0)

    victim = Victim(query=query, kind="discrete", obs_shape=(5, 5))
    x0 = np.random.default_rng(0).integers(0, 256, size=(6, 5, 5)).astype(np.uint8)
    x0[:, :, 1] = np.array([0, 1, 254, 255, 3], dtype=np.uint8)  # at the box's edges
    spec = AttackSpec(attack=name, **readable(name, eps=3.5, steps=4, n_directions=3, step_size=2.0, mu=1.0,
                                                    frozen=[]))
    attack, objective, oracle = spec.build(victim, features=("presence", "x", "y", "vx", "vy"), bounds=(0.0, 255.0),
                                           n_actions=5)
    result = attack.perturb(x0, oracle, objective)
    assert result.x_adv.dtype == np.uint8
    delta = result.x_adv.astype(np.float64) - x0
    assert np.abs(delta).max() <= 3.5 and result.linf.max() <= 3.5
    points = np.concatenate([s.reshape(len(s), -1) for s in seen])
    assert np.array_equal(points, np.round(points)) and points.min() >= 0 and points.max() <= 255
