"""Vertex hold and vertex check (`attacks.hold`): one counted query per step, never the clean
observation; a perturbation kept while the victim takes the target, a fresh vertex after a step it
did not (vertex hold) or instead of one the check says fails (vertex check)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from toys import blind_picker, context, linear_victim, observations
from zodrive.attacks import AttackSpec
from zodrive.attacks.spec import load_attack
from zodrive.attacks.picker import Picker
from zodrive.attacks.victim import Victim
from zodrive.errors import ZodriveError

EPS = 0.1


def gate_victim(seen: list[np.ndarray]) -> Victim:
    """Takes FASTER (3) exactly when vehicle 1's x is above 0, else IDLE (1); keeps every batch."""

    def scores(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=np.float32)
        out = np.zeros((len(x), 5), dtype=np.float32)
        out[:, 1] = 0.5
        out[:, 3] = np.where(x[:, 1, 1] > 0, 1.0, 0.0)
        return out

    def query(x: np.ndarray) -> np.ndarray:
        seen.append(np.array(x, dtype=np.float32, copy=True))
        return scores(x)

    return Victim(query=query, kind="discrete", obs_shape=(5, 5), calibrate=scores)  # calibration: unrecorded


BOTH = pytest.mark.parametrize("name", ["vertex-hold", "vertex-check"])


def build(victim: Victim, name: str = "vertex-hold", **kw):
    if name == "vertex-check":  # vertex check runs with a picker only
        kw = {"adversary": blind_picker(EPS), **kw}
    return AttackSpec(attack=name, eps=EPS, **kw).build(victim, **context("discrete"))


def test_it_holds_what_works_and_redraws_what_does_not() -> None:
    """At x = 0 on the gate coordinate half the vertices open the gate. Until one does, every
    step draws a new vertex; from then on the same perturbation is fed at every step."""
    seen: list[np.ndarray] = []
    attack, objective, oracle = build(gate_victim(seen))
    x0 = observations(1, seed=3)
    x0[0, 1, 1] = 0.0
    attack.reseed(0)  # a seed whose first three vertices miss
    fed, took = [], []
    for _ in range(12):
        result = attack.perturb(x0, oracle, objective)
        fed.append(result.x_adv[0] - x0[0])
        took.append(bool(result.success[0]))
    first = took.index(True)
    assert first == 3
    assert all(took[first:]) and not any(took[:first])
    assert all(np.array_equal(d, fed[first]) for d in fed[first:])  # held
    assert all(not np.array_equal(fed[i], fed[i + 1]) for i in range(first))  # redrawn after a miss


@BOTH
def test_one_counted_query_per_row_per_step_on_a_vertex_and_never_the_clean_observation(name: str) -> None:
    seen: list[np.ndarray] = []
    attack, objective, oracle = build(gate_victim(seen), name)
    x0 = observations(6, seed=4)
    attack.reseed(list(range(6)))
    for _ in range(5):
        result = attack.perturb(x0, oracle, objective)
        assert np.array_equal(result.queries, np.ones(6))
        delta = result.x_adv - x0
        np.testing.assert_array_equal(delta[:, :, 0], 0.0)  # presence is frozen
        inside = np.abs(x0[:, :, 1:]) < 1 - EPS  # not clipped by the box: exactly on a vertex
        np.testing.assert_allclose(np.abs(delta[:, :, 1:])[inside], EPS, rtol=1e-5)
        assert np.isnan(result.clean_outputs).all() and not result.already.any()
        asked = ~np.isnan(result.adv_outputs).any(axis=1)  # vertex check: a vertex fed unasked has no outputs
        assert asked.all() or name == "vertex-check"
        np.testing.assert_array_equal(result.success, asked & (np.nan_to_num(result.adv_outputs).argmax(1) == 3))
    sent = np.concatenate(seen)
    assert oracle.total_queries == len(sent) == 30  # the calibration went to the harness's copy, unseen
    asked = np.concatenate(seen[-5:])  # the attack's own calls
    assert [len(batch) for batch in seen[-5:]] == [6] * 5 and not any(np.array_equal(s, x) for s in asked for x in x0)


@BOTH
def test_rows_in_lockstep_get_what_one_row_runs_get_and_a_seed_repeats_them(name: str) -> None:
    x0 = observations(4, seed=5)
    victim = linear_victim(seed=2)

    def run(rows: list[int]) -> np.ndarray:
        attack, objective, oracle = build(victim, name)
        attack.reseed([11 + r for r in rows])
        return np.stack([attack.perturb(x0[rows], oracle, objective).x_adv for _ in range(6)])

    together = run([0, 1, 2, 3])
    for r in range(4):
        np.testing.assert_array_equal(together[:, r], run([r])[:, 0])
    np.testing.assert_array_equal(together, run([0, 1, 2, 3]))


@pytest.mark.parametrize(("options", "message"), [
    ({"target": "none"}, "give it a fixed target"),
    ({"target": "worst"}, "not none or worst"),  # its success reads the clean outputs, never asked
    ({"norm": "l2"}, "use norm linf"),
    ({"steps": 20}, "steps has no effect"),
    ({"warm_start": True}, "warm_start has no effect"),
    ({"mu": 0.3}, "mu has no effect"),
    ({"kappa": 5.0}, "kappa has no effect"),
    ({"target": "FASTER,not:SLOWER"}, "the fallback of target FASTER,not:SLOWER would be ignored"),
])
@BOTH
def test_what_it_cannot_do_is_a_one_line_error(options: dict, message: str, name: str) -> None:
    with pytest.raises(ZodriveError, match=message):
        build(linear_victim(), name, **options)
    if "norm" not in options and "steps" not in options and "warm_start" not in options:
        with pytest.raises(ZodriveError, match=message):  # and before any episode runs (`zodrive compare`)
            AttackSpec(attack=name, eps=EPS, **options, **({"adversary": blind_picker(EPS)} if name == "vertex-check"
                                                              else {})).check()


def test_the_vertex_is_held_whole_where_the_box_clipped_it() -> None:
    """A coordinate at the box's edge clips the vertex at one step; once the observation has moved
    away, the held vertex is fed whole (eps), not the clipped remainder (0)."""
    seen: list[np.ndarray] = []
    attack, objective, oracle = build(gate_victim(seen))
    x0 = observations(1, seed=3)
    x0[0, 1, 1], x0[0, 2, 2] = 0.0, 1.0  # the gate, and a value at the box's upper edge
    attack.reseed(3)  # a seed whose winning vertex is +eps at the edge coordinate
    while not attack.perturb(x0, oracle, objective).success[0]:
        pass
    clipped = attack.perturb(x0, oracle, objective)  # held: the same vertex again
    assert clipped.success[0] and clipped.x_adv[0, 2, 2] == 1.0  # clipped at the edge (this seed's sign is +)
    moved = x0.copy()
    moved[0, 2, 2] = 0.5
    whole = attack.perturb(moved, oracle, objective)
    assert whole.x_adv[0, 2, 2] == pytest.approx(0.5 + EPS)


def test_the_summary_says_no_base_rate_is_known() -> None:
    from zodrive.evaluation.report import format_summary

    summary = {"episodes": 2, "seed": 1, "mean_return": 1.0, "ci95": [0.5, 1.5], "max_return": 2.0,
               "collision_rate": 0.5, "mean_length": 10.0, "attack": "vertex-hold", "eps": 0.02, "norm": "linf",
               "mode": "budgeted", "target": "auto", "attack_success_rate": 0.75, "target_base_rate": None,
               "queries_per_step": 1.0, "max_linf": 0.02, "attack_config": {}}
    text = format_summary(summary)
    assert "the target taken on 75.0% of steps" in text and "no base rate" in text and "1.0 queries/step" in text


def test_vertex_check_s_summary_says_what_its_success_counts() -> None:
    from zodrive.evaluation.report import format_summary

    summary = {"episodes": 2, "seed": 1, "mean_return": 1.0, "ci95": [0.5, 1.5], "max_return": 2.0,
               "collision_rate": 0.5, "mean_length": 10.0, "attack": "vertex-check", "eps": 0.02, "norm": "linf",
               "mode": "budgeted", "target": "auto", "attack_success_rate": 0.6, "target_base_rate": None,
               "queries_per_step": 0.805, "max_linf": 0.02, "attack_config": {"check_below": 0.998}}
    text = format_summary(summary)
    assert "a check confirmed the target on 60.0% of steps" in text and "fed unasked is not counted" in text
    assert "0.81 queries/step" in text and "check_below=0.998" in text


def test_a_default_compare_grid_leaves_out_what_cannot_take_its_options() -> None:
    """`zodrive compare` without --attacks runs every attack that takes --attack-set: vertex-hold
    is left out (and named) with an untargeted objective or a search option, kept otherwise."""
    from zodrive.attacks.registry import ATTACKS
    from zodrive.experiments.compare import default_attacks

    assert default_attacks([]) == ([name for name in ATTACKS if name != "vertex-check"], {})  # it needs a picker
    names, left_out = default_attacks(["target=none"])
    assert "vertex-hold" not in names and "random-search" in names and "fixed target" in left_out["vertex-hold"]
    names, left_out = default_attacks(["steps=50"])
    assert set(left_out) == {"vertex-hold", "uniform-noise", "fgsm"}  # neither runs T iterations
    assert all("steps has no effect" in why for why in left_out.values())


def flipping_gate_victim() -> Victim:
    """Takes FASTER (3) exactly when vehicle 1's x has the sign of vehicle 2's x, else IDLE (1). With
    vehicle 1's x at 0 and vehicle 2's at +-0.5 (beyond eps), half the vertices work, and which half
    flips with vehicle 2's sign."""

    def query(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=np.float32)
        out = np.zeros((len(x), 5), dtype=np.float32)
        out[:, 1] = 0.5
        out[:, 3] = np.where(x[:, 1, 1] * x[:, 2, 1] > 0, 1.0, 0.0)
        return out

    return Victim(query=query, kind="discrete", obs_shape=(5, 5))


def test_vertex_check_never_feeds_a_vertex_its_check_says_fails_and_misses_fewer_steps() -> None:
    """The clean observation flips which half of the vertices works every third step. Vertex hold
    feeds its held vertex and misses every flip; vertex check asks first, feeds a fresh vertex where
    the held one fails, and misses only where that fresh vertex fails too (half the time here)."""
    victim = flipping_gate_victim()
    x0 = observations(1, seed=7)
    x0[0, 1, 1] = 0.0
    states = []
    for t in range(60):
        x = x0.copy()
        x[0, 2, 1] = 0.5 if (t // 3) % 2 == 0 else -0.5
        states.append(x)
    missed = {"vertex-hold": 0, "vertex-check": 0}
    for name in missed:
        for seed in range(5):
            attack, objective, oracle = build(victim, name)
            attack.reseed(seed)
            fed_before = None
            for x in states:
                result = attack.perturb(x, oracle, objective)
                took = victim.query(result.x_adv).argmax(1)[0] == 3  # what the victim did (the evaluator's view)
                missed[name] += not took
                assert int(result.queries[0]) == 1
                if name == "vertex-check":
                    asked = not np.isnan(result.adv_outputs).any()
                    assert bool(result.success[0]) == asked  # fed the asked vertex exactly when the check said yes
                    if asked:
                        assert took
                    elif fed_before is not None:  # the held vertex failed its check: a fresh one is fed
                        assert not np.array_equal(result.x_adv - x, fed_before)
                fed_before = result.x_adv - x
    # over 5 seeds: hold misses every flip (19 each) and half the steps after a miss; check about half that
    assert missed["vertex-hold"] >= 5 * 19
    assert missed["vertex-check"] <= 0.6 * missed["vertex-hold"]


class _Product(torch.nn.Module):
    """The logit `gain` * x[1, 1] * x[2, 1] of a flattened (5, 5) observation."""

    def __init__(self, gain: float) -> None:
        super().__init__()
        self.gain = gain

    def forward(self, flat: torch.Tensor) -> torch.Tensor:
        return self.gain * flat[:, 6:7] * flat[:, 11:12]


def gate_picker(gain: float, candidates: int = 8) -> Picker:
    """A picker for `flipping_gate_victim`: rates a fed observation by the sign the gate reads (a large
    `gain`: right on every vertex; a negative one: always wrong)."""
    identity = torch.nn.Linear(25, 25, bias=False)
    with torch.no_grad():
        identity.weight.copy_(torch.eye(25))
    return Picker(torch.nn.Sequential(identity, _Product(gain)), candidates=candidates, switch=0.0)


def half_picker() -> Picker:
    """A picker that reads only vehicle 2's x: sure of every vertex while it is positive, of none while it is not."""
    half = torch.nn.Linear(25, 1, bias=False)
    with torch.no_grad():
        half.weight.zero_()
        half.weight[0, 11] = 50.0
    return Picker(torch.nn.Sequential(half), candidates=8, switch=0.0)


def checked(victim: Victim, picker: Picker, check_below: float):
    """Vertex check with an in-memory picker (a folder's picker is an MLP; these toys are exact) and `check_below`."""
    attack, objective, oracle = build(victim, "vertex-check")
    attack.use_picker(picker, {"target": 3, "tol": None})
    attack.check_below = check_below
    return attack, objective, oracle


def flipping_states(steps: int, every: int = 3) -> list[np.ndarray]:
    x0 = observations(1, seed=7)
    x0[0, 1, 1] = 0.0
    states = []
    for t in range(steps):
        x = x0.copy()
        x[0, 2, 1] = 0.5 if (t // every) % 2 == 0 else -0.5
        states.append(x)
    return states


def test_check_below_skips_the_checks_a_picker_is_sure_of_and_spends_them_where_a_check_fails() -> None:
    """With a picker that is right, a held vertex rated high is fed unasked (no query that step), and
    where the gate flips the saved query checks a fresh vertex: no step is missed after the first, and
    no prefix of the episode spends more queries than its steps."""
    victim = flipping_gate_victim()
    attack, objective, oracle = checked(victim, gate_picker(200.0), check_below=0.9)
    spent, misses, free = 0, 0, 0
    attack.reseed(4)
    for t, x in enumerate(flipping_states(60)):
        result = attack.perturb(x, oracle, objective)
        spent += int(result.queries[0])
        assert spent <= t + 1
        free += int(result.queries[0]) == 0
        misses += t > 0 and victim.query(result.x_adv).argmax(1)[0] != 3
    assert misses == 0 and free >= 30 and spent < 60


def test_check_below_never_spends_more_than_one_query_per_step_on_average_even_with_a_wrong_picker() -> None:
    """A picker that reads only vehicle 2 (sure of every vertex while its x is positive, of none while it is
    negative): whatever it says, every prefix of every episode (rows in lockstep, one restarted) spends at
    most one query per step so far, and the queries saved are spent where checks fail."""
    victim = flipping_gate_victim()
    attack, objective, oracle = checked(victim, half_picker(), 0.5)
    states = flipping_states(40, every=2)
    attack.reseed([1, 2, 3])
    spent, steps, most = np.zeros(3, dtype=int), np.zeros(3, dtype=int), 0
    for t, x in enumerate(states):
        if t == 20:  # row 1 starts a new episode
            attack.restart_row(1, 9)
            oracle.begin_episode(1)
            spent[1] = steps[1] = 0
        result = attack.perturb(np.repeat(x, 3, axis=0), oracle, objective)
        spent += result.queries
        steps += 1
        most = max(most, int(result.queries.max()))
        assert (spent <= steps).all(), (t, spent, steps)
    assert most > 1  # the bank was spent: some step checked more than one vertex


def test_vertex_check_needs_a_picker_and_check_below_a_rating() -> None:
    for options in ({}, {"check_below": 0.9}):  # vertex check without a picker was removed
        with pytest.raises(ZodriveError, match=r"vertex-check needs a picker: --attack vertex-check:DIR .*removed"):
            AttackSpec(attack="vertex-check", eps=EPS, **options)
    with pytest.raises(ZodriveError, match="vertex-check needs a picker"):
        load_attack("vertex-check")
    with pytest.raises(ZodriveError, match="check_below must be <= 1"):
        build(flipping_gate_victim(), "vertex-check", check_below=1.5)


def test_check_below_is_refused_by_every_other_attack() -> None:
    with pytest.raises(ZodriveError, match="applies to vertex-check:DIR, not vertex-hold"):
        build(flipping_gate_victim(), "vertex-hold", check_below=0.9)
    with pytest.raises(ZodriveError, match="applies to vertex-check:DIR, not random-search"):
        AttackSpec(attack="random-search", eps=EPS, check_below=0.9).check()


def test_check_below_in_lockstep_gives_what_one_row_runs_give() -> None:
    """Each row's bank, random stream and extra checks are its own: three rows attacked together get, step
    for step, what three one-row runs get."""
    victim = flipping_gate_victim()
    states = flipping_states(24, every=2)

    def run(rows: list[int]) -> tuple[np.ndarray, np.ndarray]:
        attack, objective, oracle = checked(victim, half_picker(), 0.5)
        attack.reseed([7 + r for r in rows])
        results = [attack.perturb(np.repeat(x, len(rows), axis=0), oracle, objective) for x in states]
        return np.stack([r.x_adv for r in results]), np.stack([r.queries for r in results])

    fed, queries = run([0, 1, 2])
    for r in range(3):
        alone_fed, alone_queries = run([r])
        np.testing.assert_array_equal(fed[:, r], alone_fed[:, 0])
        np.testing.assert_array_equal(queries[:, r], alone_queries[:, 0])
    assert queries.max() > 1 and queries.min() == 0  # both sides of the rule ran
