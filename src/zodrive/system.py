"""The one wrapper that applies an attack to what a policy observes.

`AttackWrapper` (a gymnasium wrapper) replaces each observation the agent receives with the
attacked one; the simulator's true state is untouched. Evaluation and adversarial training
both use it; inside SB3's vectorized envs each copy attacks its own environment. A user builds
it from a policy and an attack's name (`zodrive.AttackWrapper(env, policy, "random-search", eps=0.05)`),
the engine from an attack it has built (`AttackWrapper.from_attacker`): one class either way.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Sequence, cast

import gymnasium as gym
import numpy as np

from zodrive.attacks.base import Attack, AttackResult
from zodrive.attacks.objectives import Objective
from zodrive.attacks.oracle import QueryOracle
from zodrive.attacks.spec import AttackSpec, load_attack
from zodrive.attacks.victim import Victim
from zodrive.defense import EpisodeFilter, keeps_state, make_defense
from zodrive.defense.wrappers import FilterWrapper, RowFilters, defended_victim
from zodrive.drivers import baselines as bl
from zodrive.envs import Scenario, action_kind, attack_context, make_env, n_actions, observation_shape, \
    scenario_of_env
from zodrive.errors import ZodriveError
from zodrive.policies.loading import load_network
from zodrive.policies.policy import Policy, resolve


def episode_seed(attack_seed: int, env_seed: int) -> int:
    """The attack's random seed for an episode started with `env.reset(seed=env_seed)`."""
    return attack_seed * 1_000_003 + env_seed


def attack_observations(
    obs: np.ndarray, attack: Attack, objective: Objective, oracle: QueryOracle, *, trace: bool = False
) -> tuple[AttackResult, float]:
    """Attack a batch of clean observations; returns the result and wall time [s]."""
    _refuse_non_finite(obs)
    start = time.perf_counter()
    result = attack.perturb(obs, oracle, objective, trace=trace)
    wall = time.perf_counter() - start
    if attack.refereed:
        referee(result, obs, oracle, objective)
    return result, wall


def _refuse_non_finite(obs: np.ndarray) -> None:
    """One line, not an attack on garbage: an observation with NaN or infinite values is refused."""
    if not np.all(np.isfinite(obs)):
        raise ZodriveError("observation contains NaN or infinite values; refusing to attack it")


def referee(result: AttackResult, obs: np.ndarray, oracle: QueryOracle, objective: Objective) -> None:
    """Judge the step of an attack that asked the victim nothing (`Attack.refereed`: transfer), after it has
    returned: the victim's outputs on the clean observations `obs` and on the fed ones (the oracle's
    `referee`, counted apart) give `success`, `already` and the outputs; the attack never sees them."""
    import torch

    n = len(obs)
    out = oracle.referee(np.concatenate([np.asarray(obs, dtype=np.float32), result.x_adv.astype(np.float32)]),
                         owners=np.tile(np.arange(n), 2))
    clean, fed = torch.from_numpy(out[:n].astype(np.float32)), torch.from_numpy(out[n:].astype(np.float32))
    result.already = objective.already(clean).numpy()
    result.success = objective.success(fed[:, None], clean)[:, 0].numpy() & ~result.already
    result.clean_outputs, result.adv_outputs = clean.numpy(), fed.numpy()
    result.referee_queries = np.full(n, 2, dtype=np.int64)


def step_stats(result: AttackResult, row: int) -> dict[str, Any]:
    """The per-step record of one environment row (goes into `info["attack"]`); under a frequency
    budget it says whether the step was attacked (`attacked`; without one, every step is).

    Wall time is kept out of `info` (it would make seeded steps differ); the wrappers expose
    it as `last_wall_time`."""
    stats = {
        "queries": int(result.queries[row]),
        "iterations": int(result.iterations[row]),
        "success": bool(result.success[row]),
        "already": bool(result.already[row]),
        "linf": float(result.linf[row]),
        "l2": float(result.l2[row]),
    }
    if result.attacked is not None:
        stats["attacked"] = bool(result.attacked[row])
    if result.referee_queries is not None:
        stats["referee_queries"] = int(result.referee_queries[row])
    return stats


def preference_gap(outputs: np.ndarray) -> np.ndarray:
    """How much a discrete policy cares which action it takes (Lin et al., "Tactics of Adversarial
    Attack on Deep Reinforcement Learning Agents", IJCAI 2017): max - min of softmax over its scores,
    per row, in [0, 1). Near 0 where the choice hardly matters: a budget is spent where it is large."""
    z = np.exp(outputs - outputs.max(axis=-1, keepdims=True))
    p = z / z.sum(axis=-1, keepdims=True)
    return p.max(axis=-1) - p.min(axis=-1)


ONE_AT_A_TIME = ("a frequency budget decides an episode's steps one by one: its episodes run one at a time "
                 "(--envs 1)")


@dataclass
class Schedule:
    """An episode's frequency budget (`attack_share`, `when`): which steps the attack runs on.

    At step t (0-based) the attacked steps so far may be at most floor(share * (t + 1)): a budget
    that holds at every moment of an episode, whatever its length. `every` spends it as soon as it
    allows (share 1/k: the k-th, 2k-th, ... steps); `gap` only on a step whose preference gap
    (`preference_gap` of the victim's scores on the clean observation, read through the oracle:
    one counted query a step) is at least `min_gap`. A step not attacked feeds the clean observation."""

    share: float
    when: str
    min_gap: float | None = None
    steps: int = 0     # decision steps of the episode so far
    attacked: int = 0  # of them attacked

    @classmethod
    def of(cls, spec: AttackSpec) -> Schedule | None:
        """The schedule of `spec`, or None where it attacks every step."""
        return cls(spec.attack_share, spec.when, spec.min_gap) if spec.sparse_in_time else None

    @property
    def reads_scores(self) -> bool:
        return self.when == "gap"

    def begin_episode(self) -> None:
        self.steps = self.attacked = 0

    def decide(self, gap: float | None) -> bool:
        """Whether the next step is attacked (counted as decided): the budget allows one more and,
        under `gap`, the step's preference gap `gap` reaches `min_gap`."""
        allowed = self.attacked < math.floor(self.share * (self.steps + 1) + 1e-9)
        if self.when == "gap":
            assert gap is not None and self.min_gap is not None  # read by the caller; required by the spec
            allowed = allowed and gap >= self.min_gap
        self.steps += 1
        self.attacked += allowed
        return allowed


def clean_result(obs: np.ndarray, queries: int) -> AttackResult:
    """What a step the frequency budget skipped feeds: the clean observations `obs` (N, *obs), no
    iteration, `queries` victim queries a row (the preference gap's read, or none)."""
    n = len(obs)
    nothing = np.full((n, 0), np.nan, dtype=np.float32)  # no output of the attack's
    return AttackResult(x_adv=np.array(obs, copy=True), success=np.zeros(n, dtype=bool),
                        already=np.zeros(n, dtype=bool), iterations=np.zeros(n, dtype=np.int64),
                        queries=np.full(n, queries, dtype=np.int64), linf=np.zeros(n), l2=np.zeros(n),
                        adv_outputs=nothing, clean_outputs=nothing.copy(), attacked=np.zeros(n, dtype=bool))


class Attacker:
    """One attack's episode lifecycle, the same for one environment (`AttackWrapper`) and for N
    run in lockstep (`zodrive.evaluation.rollout.run_lockstep`): each row's random stream is
    seeded by its episode's seed, nothing is carried across episodes, and the oracle counts
    each row's queries per step and per episode. With a `schedule` (a frequency budget) it decides,
    step by step, whether to call the attack at all: the timing rule is the system's, not an attack's,
    and it runs one environment at a time."""

    def __init__(self, attack: Attack, objective: Objective, oracle: QueryOracle, *, trace: bool = False,
                 schedule: Schedule | None = None) -> None:
        self.attack, self.objective, self.oracle, self.trace = attack, objective, oracle, trace
        self.schedule = schedule

    def start(self, env_seeds: Sequence[int | None]) -> None:
        """Rows begin episodes reset with `env_seeds` (one None: an unseeded reset, whose
        attack stream goes on where it was)."""
        if self.schedule is not None:
            if len(env_seeds) != 1:
                raise ZodriveError(ONE_AT_A_TIME)
            self.schedule.begin_episode()
        if any(seed is None for seed in env_seeds):
            self.attack.begin_episode()
        else:
            seeds = cast("Sequence[int]", env_seeds)  # none is None here
            self.attack.reseed([episode_seed(self.attack.seed, int(seed)) for seed in seeds])
        self.oracle.begin_step(rows=len(env_seeds))
        self.oracle.begin_episode()

    def restart_row(self, row: int, env_seed: int) -> None:
        """Row `row` begins the episode reset with `env_seed` while the others go on."""
        if self.schedule is not None:
            raise ZodriveError(ONE_AT_A_TIME)
        self.attack.restart_row(row, episode_seed(self.attack.seed, env_seed))
        self.oracle.begin_episode(row)

    def keep_rows(self, rows: np.ndarray) -> None:
        """Only `rows` go on (their episodes ended with none waiting)."""
        self.attack.keep_rows(rows)
        self.oracle.keep_rows(rows)

    def step(self, obs: np.ndarray) -> tuple[AttackResult, float]:
        """Attack one step's observations (N rows); the result and the wall time [s]. Under a
        schedule (one row), a step it skips feeds the clean observation (`clean_result`), and the
        gap's read is counted in the step's queries whether the step is attacked or not."""
        if self.schedule is None:
            return attack_observations(obs, self.attack, self.objective, self.oracle, trace=self.trace)
        if len(obs) != 1:
            raise ZodriveError(ONE_AT_A_TIME)
        _refuse_non_finite(obs)
        start = time.perf_counter()
        self.oracle.begin_step(rows=1)
        gap = float(preference_gap(self.oracle(obs))[0]) if self.schedule.reads_scores else None
        reads = self.oracle.step_queries  # the attack's own step counts its queries from zero
        if not self.schedule.decide(gap):
            self.attack.fed_clean(obs)
            return clean_result(obs, reads), time.perf_counter() - start
        result, _ = attack_observations(obs, self.attack, self.objective, self.oracle, trace=self.trace)
        result.queries = result.queries + reads
        result.attacked = np.ones(1, dtype=bool)
        return result, time.perf_counter() - start


class AttackWrapper(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """A gymnasium wrapper that feeds the agent attacked observations of any Box-observation
    environment; `info["attack"]` has the step's stats and `info["clean_obs"]` the true
    observation (for rendering what was really there).

    `AttackWrapper(env, policy, attack="random-search", eps=0.05)` (`zodrive.AttackWrapper`) reads
    the threat model's features and bounds and the target's actions from `env` (highway-env's
    observer, or the observation space's box); the default target is the paper's (FASTER) where
    the environment has that action, else untargeted. `AttackWrapper.from_attacker` wraps an
    attack already built (the engine's way: `make_attacked_env`, against a preset).

    :param env: the environment (reset once here, with seed 0, to read highway-env's observer).
    :param policy: the victim the attacker queries (anything `zodrive.evaluate` takes); None with an `Attacker`.
    :param attack: the attack's name or `AttackSpec`, or an `Attacker` already built against its
        victim (what `from_attacker` passes, and gymnasium's `env.spec` records to rebuild it).
    :param options: the attack's options (`eps=0.05`, ...).
    """

    def __init__(self, env: gym.Env, policy: Any, attack: str | AttackSpec | Attacker = "random-search",
                 **options: Any) -> None:
        if not isinstance(env, gym.Env):
            raise ZodriveError(f"AttackWrapper wraps a gymnasium environment, not a {type(env).__name__}")
        if isinstance(attack, Attacker):
            if policy is not None or options:
                raise ZodriveError("an Attacker already queries its victim: give it without a policy or options")
            attacker = attack
            # copied, as gymnasium does by default: `env.spec.make()` gets an attacker of its own
            gym.utils.RecordConstructorArgs.__init__(self, policy=None, attack=attacker)
        else:
            # the caller's own arguments, not copied (a model can be large): `env.spec.make()` builds anew from them
            gym.utils.RecordConstructorArgs.__init__(self, _disable_deepcopy=True, policy=policy, attack=attack,
                                                     **options)
            where = scenario_of_env(env)
            spec = spec_for(attack, where, options)
            assert spec is not None  # an attack is named
            attacker = Attacker(*build_attacker(spec, resolve(policy).victim_on(where), where),
                                schedule=Schedule.of(spec))
        gym.ObservationWrapper.__init__(self, env)
        self.attacker = attacker
        self.attack, self.objective, self.oracle = attacker.attack, attacker.objective, attacker.oracle
        self.last: AttackResult | None = None
        self.last_stats: dict[str, Any] = {}
        self.last_wall_time = 0.0  # [s] spent attacking the latest observation
        self.clean_obs: np.ndarray | None = None
        self._episode_hits = self._episode_applicable = 0

    @classmethod
    def from_attacker(cls, env: gym.Env, attack: Attack, objective: Objective, oracle: QueryOracle, *,
                      trace: bool = False, schedule: Schedule | None = None) -> AttackWrapper:
        """The wrapper around an attack already built against its victim (`build_attacker`)."""
        return cls(env, None, Attacker(attack, objective, oracle, trace=trace, schedule=schedule))

    def observation(self, observation: np.ndarray) -> np.ndarray:
        self.clean_obs = observation
        result, wall = self.attacker.step(observation[None])
        self.last, self.last_stats, self.last_wall_time = result, step_stats(result, 0), wall
        if result.attacked is None or result.attacked[0]:
            self._episode_hits += int(result.success[0])
            self._episode_applicable += int(not result.already[0])
        return result.x_adv[0]

    def reset(self, **kwargs: Any):
        """Reset; a seeded reset also restarts the attack's random stream from that seed, so an
        episode's perturbations depend only on (attack seed, episode seed)."""
        self.attacker.start([kwargs.get("seed")])
        self._episode_hits = self._episode_applicable = 0
        obs, info = super().reset(**kwargs)
        return obs, self._info(info)

    def step(self, action: Any):
        """Step; the observation an episode ends on is passed on clean and not attacked: no one
        acts on it, so querying the victim about it would spend queries no step is charged."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        if terminated or truncated:
            self.clean_obs, self.last, self.last_stats, self.last_wall_time = obs, None, {}, 0.0
            return obs, reward, terminated, truncated, self._info(info)
        return self.observation(obs), reward, terminated, truncated, self._info(info)

    def _info(self, info: dict[str, Any]) -> dict[str, Any]:
        info = dict(info)
        info["attack"] = dict(self.last_stats)
        info["clean_obs"] = self.clean_obs
        # running episode figures, flat so that SB3's Monitor can log them at episode end
        info["attack_success_rate"] = self._episode_hits / max(self._episode_applicable, 1)
        info["attack_queries"] = self.oracle.episode_queries
        return info


def spec_for(attack: str | AttackSpec | None, where: Scenario, options: dict[str, Any]) -> AttackSpec | None:
    """The attack spec of the Python API from a name (or spec) and keyword options; the default
    target is the paper's where the scenario has that action, else untargeted."""
    if attack is None:
        if options:
            raise ZodriveError(f"attack options {sorted(options)} given without an attack")
        return None
    spec = attack if isinstance(attack, AttackSpec) else load_attack(attack)
    if "target" not in options and spec.target == "auto" and not _paper_target_fits(where):
        options = {**options, "target": "none"}
    return spec.with_overrides(**options) if options else spec


def _paper_target_fits(where: Scenario) -> bool:
    if where.kind == "discrete":
        return "FASTER" in where.action_names
    return tuple(where.action_names) == ("acceleration", "steering")


def build_attacker(spec: AttackSpec, victim: Victim,
                   where: dict[str, Any] | Scenario) -> tuple[Attack, Objective, QueryOracle]:
    """The attack `spec` against `victim` on the observation of `where` (a preset, or the
    `Scenario` of an environment: its features, box and actions), with the safe loader for a
    learned adversary's network: the one place an attack is put together."""
    context = where.attack_context() if isinstance(where, Scenario) else attack_context(where)
    return spec.build(victim, **context, load_network=load_network)


def make_attacked_env(preset: dict[str, Any], victim: Victim, spec: AttackSpec | None = None, *,
                      render_mode: str | None = None, trace: bool = False) -> gym.Env:
    """The preset's environment, wrapped in `AttackWrapper` when an `AttackSpec` is given."""
    env = make_env(preset, render_mode=render_mode)
    if spec is None:
        return env
    attack, objective, oracle = build_attacker(spec, victim, preset)
    return AttackWrapper.from_attacker(env, attack, objective, oracle, trace=trace, schedule=Schedule.of(spec))


def make_policy_env(model: Policy | str | Any, preset: dict[str, Any], spec: AttackSpec | None = None, *,
                    render_mode: str | None = None, trace: bool = False, defense: str | None = None,
                    trust: bool = False) -> tuple[Victim, gym.Env]:
    """The policy's victim and the preset's environment, wrapped in the attack `spec` if given
    and, with `defense`, in the defense between the (attacked) sensor and the policy; the
    attacker then queries the defended system. `model` is anything `resolve` reads."""
    policy = resolve(model)
    if policy.reads_simulator:
        policy.check(preset, attacked=spec is not None)
        if defense is not None:
            raise ZodriveError(f"{policy.ref} reads the simulator: an observation defense does not apply to it")
        env = make_env(preset, render_mode=render_mode)
        kind = action_kind(preset)
        assert policy.baseline is not None  # only baselines read the simulator
        driver = bl.simulator_driver(policy.baseline, env, preset, kind)
        victim = bl.driver_victim(driver, kind, observation_shape(preset), n_actions(preset))
        return victim, env
    if defense is None or not keeps_state(defense):
        victim = load_policy(policy, preset, defense, trust=trust)
        return victim, make_attacked_env(preset, victim, spec, render_mode=render_mode, trace=trace)
    victim = _own_victim(policy, preset, defense, trust)
    filt = cast(EpisodeFilter, make_defense(defense, preset))  # it keeps state: an EpisodeFilter
    env = make_attacked_env(preset, defended_victim(victim, filt), spec, render_mode=render_mode, trace=trace)
    return victim, FilterWrapper(env, filt)


def load_policy(model: Policy | str | Any, preset: dict[str, Any], defense: str | None = None, *,
                trust: bool = False) -> Victim:
    """What drives and what the attacker queries when nothing keeps per-episode state: the
    policy's victim, behind a stateless defense (a shield, smoothing) if one is named."""
    victim = _own_victim(model, preset, defense, trust)
    if defense is None:
        return victim
    if keeps_state(defense):
        raise ZodriveError(f"the {defense} defense tracks an episode: it wraps the environment (make_policy_env)")
    return make_defense(defense, preset).guard(victim)  # type: ignore[union-attr]


def load_policy_rows(model: Policy | str | Any, preset: dict[str, Any], defense: str | None = None, *,
                     trust: bool = False) -> tuple[Victim, RowFilters | None]:
    """What drives N episodes side by side: the policy (behind a stateless defense, as `load_policy`),
    or, for a defense that tracks an episode, the policy alone and one filter per row (`RowFilters`,
    which `run_lockstep` puts in front of the policy and of the attacker's queries)."""
    if defense is None or not keeps_state(defense):
        return load_policy(model, preset, defense, trust=trust), None
    return _own_victim(model, preset, defense, trust), RowFilters(lambda: cast(EpisodeFilter,
                                                                                make_defense(defense, preset)))


def _own_victim(model: Policy | str | Any, preset: dict[str, Any], defense: str | None, trust: bool) -> Victim:
    """The policy's own victim, before any defense: refused in one line where `defense` would stand in front of
    a policy that reads no observation (`defense_applies`); `Policy.victim` checks that it fits the preset."""
    policy = resolve(model)
    defense_applies(policy, defense)
    return policy.victim(preset, trust=trust)


def defense_applies(policy: Policy, defense: str | None) -> None:
    """A defense in front of a policy that reads no observation would change nothing: refused, one line."""
    if defense is not None and policy.reads == "nothing":
        raise ZodriveError(f"{policy.ref} takes one constant action whatever it observes: the {defense} defense "
                           "between its sensor and it changes nothing (evaluate it without --defense)")
