"""Episode rollouts: a victim drives an (optionally attacked) environment; records come out."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Callable, Iterator, SupportsFloat

import gymnasium as gym
import numpy as np

from zodrive.attacks.base import Attack
from zodrive.attacks.objectives import Objective
from zodrive.attacks.oracle import QueryOracle
from zodrive.attacks.victim import Victim
from zodrive.defense.wrappers import RowFilters
from zodrive.system import Attacker, AttackWrapper, step_stats


@dataclass
class EpisodeRecord:
    episode: int
    seed: int
    return_: float
    pct_of_max: float
    length: int
    crashed: bool
    offroad: bool              # ended by leaving the road (continuous preset: offroad_terminal)
    mean_speed: float          # [m/s]
    right_lane_share: float    # fraction of steps in the right-most lane
    lane_changes: int = 0      # lane boundaries the ego crossed
    distance: float = 0.0      # [m] x-displacement from the start (kept for old records; see path_length)
    path_length: float | None = None   # [m] the length of the path the ego drove (sum of its step displacements)
    on_road_share: float | None = None  # share of steps that ended with the ego on the road
    queries: int = 0           # attack queries over the episode
    attacked_steps: int = 0
    successes: int = 0         # steps where the attack met its goal (not already met)
    applicable: int = 0        # steps where the clean policy did not already meet it
    max_linf: float = 0.0
    action_counts: list[int] | None = None
    referee_queries: int = 0   # rows the harness sent the victim to judge a transfer attack's steps (0: none)

    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        data["return"] = data.pop("return_")
        if not data["referee_queries"]:  # written only where a referee ran: other records stay as they were
            del data["referee_queries"]
        return data


def act(victim: Victim, obs: np.ndarray, space: gym.Space | None = None) -> Any:
    """The victim's deterministic action on one observation (not an attack query); a
    continuous action is kept inside the action space's box (default [-1, 1])."""
    return to_action(victim, victim.query(obs[None]), space)


def to_action(victim: Victim, out: np.ndarray, space: gym.Space | None = None) -> Any:
    """`act`'s action from the victim's outputs `out` on one observation (a batch of one)."""
    action = victim.actions(out)[0]
    if victim.kind == "discrete":
        return int(action)
    if isinstance(space, gym.spaces.Box):
        return np.clip(action, space.low, space.high)
    return np.clip(action, -1.0, 1.0)


def clean_states(env: gym.Env, victim: Victim, seed: int, count: int) -> np.ndarray:
    """`count` observations the victim meets driving clean from `env.reset(seed=seed)`; an
    episode that ends is followed by one reset with seed `seed + states so far`."""
    return states_driven(env, lambda obs: act(victim, obs, env.action_space), seed, count)


def states_driven(env: gym.Env, choose: Callable[[np.ndarray], Any], seed: int, count: int) -> np.ndarray:
    """`count` observations met acting with `choose(observation) -> action`, called once per
    step, from `env.reset(seed=seed)`; an episode that ends is followed by one reset with seed
    `seed + states so far`."""
    obs, _ = env.reset(seed=seed)
    states = []
    for _ in range(count):
        states.append(obs)
        obs, _, terminated, truncated, _ = env.step(choose(obs))
        if terminated or truncated:
            obs, _ = env.reset(seed=seed + len(states))
    return np.stack(states)


class Episode:
    """The running figures of one episode, fed step by step (`acted`, `stepped`); `record()`
    makes its `EpisodeRecord`. Driving metrics (speed, lanes, distance) are read on
    highway-env roads only; elsewhere they stay empty."""

    def __init__(self, env: gym.Env, policy: Victim, *, episode: int, seed: int, max_return: float | None) -> None:
        self.env, self.episode, self.seed, self.max_return = env, episode, seed, max_return
        self.road = hasattr(env.unwrapped, "vehicle") and hasattr(env.unwrapped, "road")
        core: Any = env.unwrapped  # on a road: a highway-env AbstractEnv (untyped)
        ego: Any = core.vehicle if self.road else None  # read for the driving metrics only; the policy sees `obs`
        self.lane: int | None
        self.start_x, self.lane = (float(ego.position[0]), ego.lane_index[2]) if self.road else (0.0, None)
        self.position = np.array(ego.position, dtype=float) if self.road else None
        self.path, self.on_road = 0.0, 0
        self.lane_changes = self.length = self.right = 0
        self.total = 0.0
        self.speeds: list[float] = []
        self.crashed = self.terminated = False
        self.queries = self.successes = self.applicable = self.attacked_steps = self.referee = 0
        self.max_linf = 0.0
        space = env.action_space
        self.counts = (np.zeros(int(space.n), dtype=np.int64)
                       if policy.kind == "discrete" and hasattr(space, "n") else None)

    def acted(self, action: Any, attack: dict[str, Any] | None) -> None:
        """The policy chose `action` on an observation the attack's step `attack` made (None: clean); a
        step a frequency budget skipped (`attacked` false) counts only its queries (the gap's read)."""
        if self.counts is not None:
            self.counts[action] += 1
        if attack is not None:
            self.queries += attack["queries"]
            self.referee += attack.get("referee_queries", 0)
        if attack is not None and attack.get("attacked", True):
            self.attacked_steps += 1
            self.successes += attack["success"]
            self.applicable += not attack["already"]
            self.max_linf = max(self.max_linf, attack["linf"])

    def stepped(self, reward: SupportsFloat, terminated: bool, info: dict[str, Any]) -> None:
        self.total += float(reward)
        self.length += 1
        self.speeds.append(float(info.get("speed", np.nan)))
        self.right += float(info.get("rewards", {}).get("right_lane_reward", 0.0)) >= 1.0
        self.crashed = bool(info.get("crashed", False))
        self.terminated = terminated
        if self.road:
            core: Any = self.env.unwrapped
            ego = core.vehicle
            self.lane_changes += ego.lane_index[2] != self.lane
            self.lane = ego.lane_index[2]
            position = np.array(ego.position, dtype=float)
            self.path += float(np.linalg.norm(position - self.position))
            self.position = position
            self.on_road += bool(ego.on_road)

    def record(self) -> EpisodeRecord:
        road, env = self.road, self.env
        core: Any = env.unwrapped
        return EpisodeRecord(
            episode=self.episode, seed=self.seed, return_=self.total,
            pct_of_max=100.0 * self.total / self.max_return if self.max_return else float("nan"),
            length=self.length, crashed=self.crashed, offroad=left_road(env, self.terminated, self.crashed),
            mean_speed=float(np.nanmean(self.speeds)) if road and self.speeds else float("nan"),
            right_lane_share=self.right / max(self.length, 1), lane_changes=int(self.lane_changes),
            distance=float(core.vehicle.position[0]) - self.start_x if road else 0.0, queries=self.queries,
            path_length=self.path if road else None,
            on_road_share=self.on_road / max(self.length, 1) if road else None,
            attacked_steps=int(self.attacked_steps), successes=int(self.successes),
            applicable=int(self.applicable), max_linf=self.max_linf,
            action_counts=self.counts.tolist() if self.counts is not None else None,
            referee_queries=int(self.referee),
        )


def run_episode(
    env: gym.Env,
    victim: Victim,
    *,
    episode: int,
    seed: int,
    max_return: float | None,
    on_step: Callable[[dict[str, Any]], None] | None = None,
    policy: Victim | None = None,
    on_tick: Callable[[int], None] | None = None,
) -> EpisodeRecord:
    """Roll out one episode from `env.reset(seed=seed)`.

    If `env` is wrapped in an `AttackWrapper`, the policy sees attacked observations and each
    step's attack stats go to `on_step`. `policy` (default: `victim`) chooses the actions.
    `max_return` None: no percentage of the maximum. `on_tick(1)` after every environment step (progress).
    """
    policy = policy or victim
    wrapper = find_attack_wrapper(env)
    attacked = wrapper is not None
    obs, info = env.reset(seed=seed)
    tracker = Episode(env, policy, episode=episode, seed=seed, max_return=max_return)
    space = env.action_space
    pending = info.get("attack") if attacked else None
    done = False
    while not done:
        action = act(policy, obs, space)
        tracker.acted(action, pending)
        if pending is not None and on_step is not None:
            assert wrapper is not None  # `pending` is the attack wrapper's
            on_step({"episode": episode, "step": tracker.length, "action": _plain(action), **pending,
                     "wall_time": wrapper.last_wall_time})
        obs, reward, terminated, truncated, info = env.step(action)
        tracker.stepped(reward, terminated, info)
        pending = info.get("attack") if attacked else None
        done = terminated or truncated
        if on_tick is not None:
            on_tick(1)
    return tracker.record()


def run_lockstep(
    envs: list[gym.Env],
    victim: Victim,
    episodes: list[tuple[int, int]],
    *,
    max_return: float | None,
    attacker: tuple[Attack, Objective, QueryOracle] | None = None,
    on_step: Callable[[dict[str, Any]], None] | None = None,
    on_tick: Callable[[int], None] | None = None,
    filters: RowFilters | None = None,
) -> Iterator[EpisodeRecord]:
    """Roll out `episodes` ((index, seed) pairs) side by side, one per environment of `envs`;
    an environment whose episode ends starts the next one waiting. Records come out as
    episodes end.

    Under attack, the N observations of a step are attacked in one call, each row with its
    own random stream (seeded per episode as the attack wrapper seeds it), budgets and
    carried state, and the oracle sends no row's queries in a batch that would change their
    outputs; the policy acts on each row alone as in `run_episode`. So every episode is,
    bit for bit, what `run_episode` gives for its seed; only the time per step is shared
    (`wall_time` is the step's attack time divided by the rows attacked). The policy must
    be memoryless and read only the observation (no simulator); a stateful defense comes as
    `filters`, one per row: each row's policy receives its own filter's output and the
    attacker queries each row through it (the oracle's `front`).
    """
    waiting = list(episodes)
    rows: list[tuple[gym.Env, Episode]] = []
    obs: list[np.ndarray] = []
    attack = Attacker(*attacker) if attacker is not None else None
    if attack is not None and filters is not None:
        attack.oracle.front = filters.peek  # the attacker queries the defended system, row by row

    def start(env: gym.Env, row: int | None) -> None:  # the next waiting episode on `env`
        index, seed = waiting.pop(0)
        if filters is not None:
            filters.start(len(rows) if row is None else row)
        first, _ = env.reset(seed=seed)
        tracker = Episode(env, victim, episode=index, seed=seed, max_return=max_return)
        if row is None:
            rows.append((env, tracker))
            obs.append(first)
        else:
            rows[row], obs[row] = (env, tracker), first
            if attack is not None:
                attack.restart_row(row, seed)

    for env in envs[: len(waiting)]:
        start(env, None)
    if attack is not None:
        attack.start([tracker.seed for _, tracker in rows])
    while rows:
        seen, result, share = np.stack(obs), None, 0.0
        if attack is not None:
            result, wall = attack.step(seen)
            seen, share = result.x_adv, wall / len(rows)
        ended = []
        for row, (env, tracker) in enumerate(rows):
            pending = None if result is None else step_stats(result, row)
            fed = seen[row] if filters is None else filters.receive(row, seen[row])
            action = act(victim, fed, env.action_space)
            tracker.acted(action, pending)
            if pending is not None and on_step is not None:
                on_step({"episode": tracker.episode, "step": tracker.length, "action": _plain(action), **pending,
                         "wall_time": share})
            obs[row], reward, terminated, truncated, info = env.step(action)
            tracker.stepped(reward, terminated, info)
            if terminated or truncated:
                yield tracker.record()
                if waiting:
                    start(env, row)
                else:
                    ended.append(row)
        if on_tick is not None:
            on_tick(len(rows))  # environment steps taken side by side (progress)
        if ended:
            keep = np.array([r for r in range(len(rows)) if r not in ended], dtype=np.int64)
            rows[:], obs[:] = [rows[r] for r in keep], [obs[r] for r in keep]
            if attack is not None:
                attack.keep_rows(keep)
            if filters is not None:
                filters.keep_rows(keep)


def left_road(env: gym.Env, terminated: bool, crashed: bool) -> bool:
    """Whether the episode ended because the ego left the road (not a crash, not an arrival:
    intersection, merge and exit end on success too)."""
    ego = getattr(env.unwrapped, "vehicle", None)
    return bool(terminated and not crashed and ego is not None and not ego.on_road)


def find_attack_wrapper(env: gym.Env) -> AttackWrapper | None:
    while isinstance(env, gym.Env):
        if isinstance(env, AttackWrapper):
            return env
        if not isinstance(env, gym.Wrapper):
            return None
        env = env.env
    return None


def _plain(action: Any) -> Any:
    return action if isinstance(action, int) else [float(a) for a in np.asarray(action)]
