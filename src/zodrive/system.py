"""The one wrapper that applies an attack to what a policy observes.

`AttackWrapper` (a gymnasium wrapper) replaces each observation the agent receives with the
attacked one; the simulator's true state is untouched. Evaluation and adversarial training
both use it; inside SB3's vectorized envs each copy attacks its own environment.
"""

from __future__ import annotations

import time
from typing import Any, Sequence, cast

import gymnasium as gym
import numpy as np

from zodrive.attacks.base import Attack, AttackResult
from zodrive.attacks.objectives import Objective
from zodrive.attacks.oracle import QueryOracle
from zodrive.attacks.spec import AttackSpec
from zodrive.attacks.victim import Victim
from zodrive.defense import EpisodeFilter, keeps_state, make_defense
from zodrive.defense.wrappers import FilterWrapper, defended_victim
from zodrive.drivers import baselines as bl
from zodrive.envs import Scenario, action_kind, attack_context, make_env, n_actions, observation_shape
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
    if not np.all(np.isfinite(obs)):
        raise ZodriveError("observation contains NaN or infinite values; refusing to attack it")
    start = time.perf_counter()
    result = attack.perturb(obs, oracle, objective, trace=trace)
    return result, time.perf_counter() - start


def step_stats(result: AttackResult, row: int) -> dict[str, Any]:
    """The per-step record of one environment row (goes into `info["attack"]`).

    Wall time is kept out of `info` (it would make seeded steps differ); the wrappers expose
    it as `last_wall_time`."""
    return {
        "queries": int(result.queries[row]),
        "iterations": int(result.iterations[row]),
        "success": bool(result.success[row]),
        "already": bool(result.already[row]),
        "linf": float(result.linf[row]),
        "l2": float(result.l2[row]),
    }


class Attacker:
    """One attack's episode lifecycle, the same for one environment (`AttackWrapper`) and for N
    run in lockstep (`zodrive.evaluation.rollout.run_lockstep`): each row's random stream is
    seeded by its episode's seed, nothing is carried across episodes, and the oracle counts
    each row's queries per step and per episode."""

    def __init__(self, attack: Attack, objective: Objective, oracle: QueryOracle, *, trace: bool = False) -> None:
        self.attack, self.objective, self.oracle, self.trace = attack, objective, oracle, trace

    def start(self, env_seeds: Sequence[int | None]) -> None:
        """Rows begin episodes reset with `env_seeds` (one None: an unseeded reset, whose
        attack stream goes on where it was)."""
        if any(seed is None for seed in env_seeds):
            self.attack.begin_episode()
        else:
            seeds = cast("Sequence[int]", env_seeds)  # none is None here
            self.attack.reseed([episode_seed(self.attack.seed, int(seed)) for seed in seeds])
        self.oracle.begin_step(rows=len(env_seeds))
        self.oracle.begin_episode()

    def restart_row(self, row: int, env_seed: int) -> None:
        """Row `row` begins the episode reset with `env_seed` while the others go on."""
        self.attack.restart_row(row, episode_seed(self.attack.seed, env_seed))
        self.oracle.begin_episode(row)

    def keep_rows(self, rows: np.ndarray) -> None:
        """Only `rows` go on (their episodes ended with none waiting)."""
        self.attack.keep_rows(rows)
        self.oracle.keep_rows(rows)

    def step(self, obs: np.ndarray) -> tuple[AttackResult, float]:
        """Attack one step's observations (N rows); the result and the wall time [s]."""
        return attack_observations(obs, self.attack, self.objective, self.oracle, trace=self.trace)


class AttackWrapper(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """Feed the policy attacked observations; `info["attack"]` has the step's stats.

    `info["clean_obs"]` keeps the true observation (for rendering what was really there).
    """

    def __init__(self, env: gym.Env, attack: Attack, objective: Objective, oracle: QueryOracle,
                 *, trace: bool = False) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, attack=attack, objective=objective, oracle=oracle, trace=trace)
        gym.ObservationWrapper.__init__(self, env)
        self.attack, self.objective, self.oracle = attack, objective, oracle
        self.attacker = Attacker(attack, objective, oracle, trace=trace)
        self.last: AttackResult | None = None
        self.last_stats: dict[str, Any] = {}
        self.last_wall_time = 0.0  # [s] spent attacking the latest observation
        self.clean_obs: np.ndarray | None = None
        self._episode_hits = self._episode_applicable = 0

    def observation(self, observation: np.ndarray) -> np.ndarray:
        self.clean_obs = observation
        result, wall = self.attacker.step(observation[None])
        self.last, self.last_stats, self.last_wall_time = result, step_stats(result, 0), wall
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
    return AttackWrapper(env, attack, objective, oracle, trace=trace)


def make_policy_env(model: Policy | str | Any, preset: dict[str, Any], spec: AttackSpec | None = None, *,
                    render_mode: str | None = None, trace: bool = False, defense: str | None = None,
                    trust: bool = False) -> tuple[Victim, gym.Env]:
    """The policy's victim and the preset's environment, wrapped in the attack `spec` if given
    and, with `defense`, in the defense between the (attacked) sensor and the policy; the
    attacker then queries the defended system. `model` is anything `resolve` reads."""
    policy = resolve(model)
    if defense is not None and policy.kind == "baseline" and bl.get_baseline(policy.ref).reads == "nothing":
        raise ZodriveError(f"{policy.ref} takes one constant action whatever it observes: the {defense} defense "
                           "between its sensor and it changes nothing (evaluate it without --defense)")
    if policy.reads_simulator:
        policy.check(preset, attacked=spec is not None)
        if defense is not None:
            raise ZodriveError(f"{policy.ref} reads the simulator: an observation defense does not apply to it")
        env = make_env(preset, render_mode=render_mode)
        kind = action_kind(preset)
        driver = bl.simulator_driver(bl.get_baseline(policy.ref), env, preset, kind)
        victim = bl.driver_victim(driver, kind, observation_shape(preset), n_actions(preset))
        return victim, env
    if defense is None or not keeps_state(defense):
        victim = load_policy(policy, preset, defense, trust=trust)
        return victim, make_attacked_env(preset, victim, spec, render_mode=render_mode, trace=trace)
    victim = policy.victim(preset, trust=trust)  # checks that the policy fits the preset
    filt = cast(EpisodeFilter, make_defense(defense, preset))  # it keeps state: an EpisodeFilter
    env = make_attacked_env(preset, defended_victim(victim, filt), spec, render_mode=render_mode, trace=trace)
    return victim, FilterWrapper(env, filt)


def load_policy(model: Policy | str | Any, preset: dict[str, Any], defense: str | None = None, *,
                trust: bool = False) -> Victim:
    """What drives and what the attacker queries when nothing keeps per-episode state: the
    policy's victim, behind a stateless defense (a shield, smoothing) if one is named."""
    victim = resolve(model).victim(preset, trust=trust)  # checks that the policy fits the preset
    if defense is None:
        return victim
    if keeps_state(defense):
        raise ZodriveError(f"the {defense} defense tracks an episode: it wraps the environment (make_policy_env)")
    return make_defense(defense, preset).guard(victim)  # type: ignore[union-attr]
