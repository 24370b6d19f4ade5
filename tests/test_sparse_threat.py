"""The sparse fields of the threat model (issue 65): sparse in space, `vehicles: k` (at most k vehicle rows of a
Kinematics observation perturbed per step, enforced by the projection), and sparse in time, a frequency budget
(`attack_share`, `when every | gap`: the system decides per step whether the attack runs at all).

Every point the victim receives is checked on the victim's side of the oracle; a step the budget skips feeds the
clean observation and spends no attack query (`when gap` spends one: the read of the preference gap, counted)."""

from __future__ import annotations

import json
import math
import shlex
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from toys import FEATURES, blind_picker, context, linear_victim, logging_victim, observations, readable
from zodrive.attacks import ATTACKS, AttackSpec
from zodrive.attacks.oracle import QueryOracle
from zodrive.attacks.threat import ThreatModel
from zodrive.attacks.victim import Victim
from zodrive.errors import ZodriveError
from zodrive.evaluation import store
from zodrive.evaluation.rollout import run_episode
from zodrive.system import AttackWrapper, Schedule, preference_gap

ROOT = Path(__file__).resolve().parents[1]
BLACK_BOX = sorted(name for name, cls in ATTACKS.items() if cls.black_box)  # every one runs with score access
EPS = 0.3


@pytest.fixture
def oracle_view(monkeypatch: pytest.MonkeyPatch) -> list[tuple[np.ndarray, np.ndarray]]:
    """Every (batch, owners) the oracle sends on to the victim."""
    seen: list[tuple[np.ndarray, np.ndarray]] = []
    call = QueryOracle.__call__

    def spy(self: QueryOracle, batch: np.ndarray, owners: np.ndarray | None = None) -> np.ndarray:
        seen.append((np.array(batch, copy=True), np.arange(len(batch)) if owners is None else np.array(owners)))
        return call(self, batch, owners)

    monkeypatch.setattr(QueryOracle, "__call__", spy)
    return seen


def _spec(name: str, **options: Any) -> AttackSpec:
    picker = {"adversary": blind_picker(options.get("eps", EPS))} if name == "vertex-check" else {}
    return AttackSpec(attack=name, **picker, **options)


def _moved_rows(points: np.ndarray, clean: np.ndarray) -> np.ndarray:
    """Per point (B, 5, 5), how many rows differ from its clean observation."""
    return np.any(points != clean, axis=-1).sum(axis=-1)


# -- sparse in space: vehicles ------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", BLACK_BOX)
@pytest.mark.parametrize("k", [1, 2])
def test_the_victim_never_receives_a_point_that_moves_more_than_k_rows(name: str, k: int, oracle_view) -> None:
    log: list[np.ndarray] = []
    x0 = observations(3, seed=7)
    x0[:, 1:, 1] = 0.999  # clean values at the edge of the box
    search = readable(name, steps=12, n_directions=5, early_stop=False)
    spec = _spec(name, eps=EPS, vehicles=k, **search)
    attack, objective, oracle = spec.build(logging_victim(linear_victim(seed=2), log), **context())
    results, sent, clean = [], [], []
    for t in range(2):  # two environment steps: the second one from the carried state, if any
        start, step = len(oracle_view), x0 - np.float32(0.01 * t)
        results.append(attack.perturb(step, oracle, objective))
        sent += [batch for batch, _ in oracle_view[start:]]
        clean += [step[owners] for _, owners in oracle_view[start:]]
    points, clean = np.concatenate(sent), np.concatenate(clean)
    assert sum(len(batch) for batch in log) == len(points) == oracle.total_queries > 3  # the spy saw every row
    moved = _moved_rows(points, clean)
    assert moved.max() == k  # the budget binds: the attack would move every row
    delta = np.abs(points - clean).reshape(len(points), -1)
    assert delta.max() <= EPS + 1e-5 and points.min() >= -1 and points.max() <= 1
    np.testing.assert_array_equal(points[:, :, 0], clean[:, :, 0])  # presence frozen
    for t, result in enumerate(results):  # and what is fed
        assert _moved_rows(result.x_adv, x0 - np.float32(0.01 * t)).max() <= k


def test_the_projection_keeps_the_rows_moved_most_and_sets_the_others_back() -> None:
    x0 = observations(1, seed=3)
    delta = np.zeros_like(x0)
    delta[0, 1, 1:] = 0.1  # L2 0.2
    delta[0, 2, 1] = 0.3   # L2 0.3
    delta[0, 3, 2] = -0.3  # L2 0.3: a tie with row 2
    delta[0, 4, 1:] = 0.05
    threat = ThreatModel(eps=0.5, features=FEATURES, vehicles=2)
    x = threat.project(x0 + delta, x0)
    np.testing.assert_array_equal(_moved_rows(x, x0), [2])
    np.testing.assert_array_equal(x[0, [0, 1, 4]], x0[0, [0, 1, 4]])
    np.testing.assert_allclose(x[0, [2, 3]], (x0 + delta)[0, [2, 3]], atol=1e-7)
    np.testing.assert_array_equal(threat.project(x, x0), x)  # a point inside stays as it is
    one = ThreatModel(eps=0.5, features=FEATURES, vehicles=1).project(x0 + delta, x0)
    np.testing.assert_array_equal(np.flatnonzero(np.any(one[0] != x0[0], axis=-1)), [2])  # the tie: the lower row
    ego = delta.copy()
    ego[0, 0, 3] = 0.4  # the ego's row counts as a row
    np.testing.assert_array_equal(
        np.flatnonzero(np.any(ThreatModel(eps=0.5, features=FEATURES, vehicles=1).project(x0 + ego, x0)[0] != x0[0],
                              axis=-1)), [0])
    dense = ThreatModel(eps=0.5, features=FEATURES).project(x0 + delta, x0)  # no vehicles: every row, as before
    np.testing.assert_array_equal(_moved_rows(dense, x0), [4])


def test_vehicles_is_refused_where_the_observation_has_no_vehicle_rows() -> None:
    flat = Victim(query=lambda x: np.zeros((len(x), 2), np.float32), kind="discrete", obs_shape=(4,))
    with pytest.raises(ZodriveError, match=r"observations of shape \(4,\) have none") as refused:
        AttackSpec(attack="random-search", vehicles=1, target="none").build(flat, (), (-5.0, 5.0), 2)
    assert "\n" not in str(refused.value)
    grid = Victim(query=lambda x: np.zeros((len(x), 5), np.float32), kind="discrete", obs_shape=(5, 11, 11))
    with pytest.raises(ZodriveError, match="have none"):  # OccupancyGrid: features along the first axis, no rows
        AttackSpec(attack="random-search", vehicles=1).build(grid, FEATURES, (-1.0, 1.0), 5, feature_axis=0)
    with pytest.raises(ZodriveError, match="vehicles 5 constrains nothing: the observation has 5 rows"):
        AttackSpec(attack="random-search", vehicles=5).build(linear_victim(), **context())


def test_the_command_line_refuses_vehicles_on_cartpole_in_one_line(capsys) -> None:
    from zodrive.cli import main

    code = main(["evaluate", str(ROOT / "tests" / "golden" / "cart_policy.py") + ":make", "--env-id", "CartPole-v1",
                 "--attack", "random-search", "--target", "none", "--vehicles", "1", "--episodes", "1"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "vehicles counts the rows of a Kinematics observation" in err


@pytest.mark.parametrize("options,message", [
    ({"vehicles": 1, "max_change": 0.01}, "vehicles with max_change"),
    ({"when": "gap"}, "give it"),
    ({"min_gap": 0.2}, "min_gap is the threshold of --when gap"),
    ({"attack": "learned", "adversary": "somewhere", "vehicles": 1}, "trained to move every row"),
])
def test_a_field_the_attack_cannot_use_is_refused_in_one_line(options: dict, message: str) -> None:
    with pytest.raises(ZodriveError, match=message) as refused:
        AttackSpec(**{"attack": "random-search", **options})
    assert "\n" not in str(refused.value)


# -- sparse in time: the frequency budget -------------------------------------------------------------------------

class Road(gym.Env):
    """A toy environment with Kinematics-shaped observations (5 vehicle rows of 5 features), 5 actions and
    `length` steps; each episode's observations are drawn from its seed."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (5, 5), np.float32)
    action_space = gym.spaces.Discrete(5)

    def __init__(self, length: int = 24) -> None:
        self.length, self.t = length, 0
        self.clean = observations(length + 1)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.t, self.clean = 0, observations(self.length + 1, seed=seed or 0)
        return self.clean[0], {}

    def step(self, action: Any):
        self.t += 1
        return self.clean[self.t], 0.0, False, self.t >= self.length, {}


def _episode(spec: AttackSpec, seed: int = 5) -> tuple[Road, list[np.ndarray], list[np.ndarray], list[dict], Any]:
    """One episode of the toy road under `spec`: the env, what the attack's victim received, what the policy
    acted on, the step records and the episode record."""
    log: list[np.ndarray] = []
    seen: list[np.ndarray] = []
    network = linear_victim(seed=2)

    def acts(x: np.ndarray) -> np.ndarray:  # the policy, which records what it acts on
        seen.append(np.array(x[0], copy=True))
        return network.query(x)

    policy = Victim(query=acts, kind="discrete", obs_shape=(5, 5))
    attack, objective, oracle = spec.build(logging_victim(network, log), **context())
    env = Road()
    wrapped = AttackWrapper.from_attacker(env, attack, objective, oracle, schedule=Schedule.of(spec))
    steps: list[dict] = []
    record = run_episode(wrapped, network, episode=0, seed=seed, max_return=None, on_step=steps.append, policy=policy)
    assert record.queries == sum(s["queries"] for s in steps) == oracle.total_queries == sum(len(b) for b in log)
    return env, log, seen, steps, record


@pytest.mark.parametrize("name", ["zo-signsgd", "random-search", "vertex-hold"])
def test_every_k_th_step_is_attacked_and_the_others_see_the_clean_observation_for_no_query(name: str) -> None:
    spec = _spec(name, eps=EPS, attack_share=0.25, **readable(name, steps=5, n_directions=4))
    env, log, seen, steps, record = _episode(spec)
    attacked = [s["attacked"] for s in steps]
    assert [t for t, a in enumerate(attacked) if a] == [3, 7, 11, 15, 19, 23]  # every 4th step
    assert record.attacked_steps == 6 and record.length == 24
    for t, s in enumerate(steps):
        if not s["attacked"]:
            assert s["queries"] == 0 and s["linf"] == 0 and s["iterations"] == 0
            np.testing.assert_array_equal(seen[t], env.clean[t])  # the policy acted on the clean observation
        else:
            assert s["queries"] >= 1
    assert any(not np.array_equal(seen[t], env.clean[t]) for t in range(24) if attacked[t])


def test_a_gap_timed_attack_reads_one_counted_query_a_step_and_attacks_only_wide_gaps_within_the_budget() -> None:
    network = linear_victim(seed=2)
    gaps = preference_gap(network.query(observations(25, seed=5)))[:24]
    min_gap = float(np.quantile(gaps, 0.4))
    spec = _spec("random-search", eps=EPS, steps=5, n_directions=4, attack_share=0.5, when="gap", min_gap=min_gap)
    env, log, seen, steps, record = _episode(spec)
    attacked = np.array([s["attacked"] for s in steps])
    assert 0 < attacked.sum() < 24 and record.attacked_steps == attacked.sum()
    assert np.all(gaps[attacked] >= min_gap)
    assert np.all(np.cumsum(attacked) <= np.floor(0.5 * np.arange(1, 25) + 1e-9))  # the budget, at every step
    skipped_wide = ~attacked & (gaps >= min_gap)  # a wide gap left alone only when the budget was spent
    assert np.all(np.cumsum(attacked)[skipped_wide] == np.floor(0.5 * (np.flatnonzero(skipped_wide) + 1)))
    for t, s in enumerate(steps):
        if not s["attacked"]:
            assert s["queries"] == 1  # the gap's read, counted
            np.testing.assert_array_equal(seen[t], env.clean[t])
    assert np.array_equal(log[0], env.clean[:1])  # the first query of the episode is the read of the clean step


def test_a_share_of_one_with_when_every_is_the_dense_attack_with_no_schedule() -> None:
    dense = _spec("random-search", eps=EPS, steps=5, n_directions=4)
    assert Schedule.of(dense) is None and Schedule.of(dense.with_overrides(attack_share=1.0)) is None
    _, _, seen_dense, steps_dense, record_dense = _episode(dense)
    assert "attacked" not in steps_dense[0] and record_dense.attacked_steps == 24


def test_the_budget_holds_at_every_step_for_any_share() -> None:
    for share in (0.05, 0.1, 0.29, 1 / 3, 0.5, 0.7, 0.999):
        schedule = Schedule(share, "every")
        taken = np.array([schedule.decide(None) for _ in range(300)])
        counts = np.cumsum(taken)
        assert np.all(counts <= share * np.arange(1, 301) + 1e-9)
        assert counts[-1] == math.floor(share * 300 + 1e-9)  # and it is spent


def test_when_gap_with_decision_access_is_refused_at_the_command_line_in_one_line(capsys) -> None:
    from zodrive.cli import main

    code = main(["evaluate", "baseline:rules", "--attack", "random-search", "--access", "decision", "--when", "gap",
                 "--min-gap", "0.1", "--episodes", "1"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "when gap reads the victim's scores" in err


def test_when_gap_on_a_continuous_victim_and_a_budget_on_a_batch_of_states_are_refused() -> None:
    with pytest.raises(ZodriveError, match="a continuous victim states none"):
        AttackSpec(attack="random-search", when="gap", min_gap=0.1).build(linear_victim(kind="continuous"),
                                                                           **context("continuous"))
    import zodrive

    with pytest.raises(ZodriveError, match="attack\\(\\) attacks one batch of states"):
        zodrive.attack(linear_victim().query, observations(2), "highway-fast", "random-search", attack_share=0.5)


def test_a_frequency_budget_runs_its_episodes_one_at_a_time() -> None:
    from zodrive.evaluation.evaluate import EvalJob, lockstep_blocker

    sparse = EvalJob(model="baseline:rules", preset={"name": "p"}, attack=AttackSpec(attack_share=0.1).to_dict())
    assert lockstep_blocker(sparse) == "a frequency budget decides an episode's steps one by one"
    dense = EvalJob(model="baseline:rules", preset={"name": "p"}, attack=AttackSpec().to_dict())
    assert lockstep_blocker(dense) is None


# -- the records: keys and summaries ------------------------------------------------------------------------------

COMMITTED = "results/close-rules/attacked/random-search-eps0.02"


def _committed_job(monkeypatch: pytest.MonkeyPatch, *extra: str):
    from zodrive.cli import build_parser
    from zodrive.cli.attack import attack_spec_from_args
    from zodrive.cli.common import preset_of
    from zodrive.evaluation.evaluate import DEFAULT_EVAL_SEED, EvalJob
    from zodrive.policies.policy import resolve

    monkeypatch.chdir(ROOT)
    command = store.summary(ROOT / COMMITTED)["command"]  # its folder, or its line in a pack
    args = build_parser().parse_args(shlex.split(command)[1:] + list(extra))
    return EvalJob(model=resolve(args.model).ref, preset=preset_of(args), attack=attack_spec_from_args(args).to_dict(),
                   seed=DEFAULT_EVAL_SEED if args.seed is None else args.seed, defense=args.defense)


def test_a_committed_cell_keeps_its_key_and_the_new_fields_change_it(monkeypatch: pytest.MonkeyPatch) -> None:
    from zodrive.attacks.schema import without_removed
    from zodrive.evaluation.evaluate import check_same_evaluation, same_evaluation

    on_disk = store.read(ROOT / COMMITTED).key
    assert not {"vehicles", "attack_share", "when", "min_gap"} & set(on_disk["attack"])  # made before the fields
    today = json.loads(json.dumps(_committed_job(monkeypatch).key()))
    assert same_evaluation(on_disk, today)
    old = without_removed(on_disk["attack"])
    assert {k: today["attack"][k] for k in old} == old  # what the cell recorded, as it recorded it
    later = set(today["attack"]) - set(old)  # options added since, at the defaults that are the behaviour it ran
    assert {"vehicles", "attack_share", "when", "min_gap"} <= later
    assert {k: today["attack"][k] for k in later} == {k: AttackSpec().to_dict()[k] for k in later}
    for extra in (["--vehicles", "1"], ["--attack-share", "0.1"], ["--attack-share", "0.5", "--when", "gap",
                                                                    "--min-gap", "0.2"]):
        changed = json.loads(json.dumps(_committed_job(monkeypatch, *extra).key()))
        assert not same_evaluation(on_disk, changed), extra
        with pytest.raises(ZodriveError, match="the attack settings"):
            check_same_evaluation(on_disk, changed, ROOT / COMMITTED)


def test_the_summary_counts_attacked_steps_and_their_queries(monkeypatch: pytest.MonkeyPatch) -> None:
    from zodrive.evaluation import evaluate as ev

    spec = _spec("random-search", eps=EPS, steps=5, n_directions=4, attack_share=0.5, when="gap", min_gap=0.0)
    _, _, _, steps, record = _episode(spec)
    for s in steps:
        s["wall_time"] = 0.0
    monkeypatch.setattr(ev, "_max_return", lambda preset: None)
    monkeypatch.setattr(ev, "eps_means", lambda preset, eps: "")
    job = ev.EvalJob(model="baseline:rules", preset={"name": "toy"}, attack=spec.to_dict())
    summary = ev.summarize([record.to_dict()], job, steps)
    assert record.attacked_steps == 12 and summary["attacked_share"] == 0.5
    assert summary["queries_per_step"] == record.queries / 12  # per attacked step, the gap's reads included
    attacked = [s for s in steps if s["attacked"]]
    assert summary["mean_linf"] == pytest.approx(np.mean([s["linf"] for s in attacked])) and summary["mean_linf"] > 0
    assert summary["target_base_rate"] == 1 - record.applicable / 12
