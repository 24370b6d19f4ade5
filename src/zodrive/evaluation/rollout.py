"""Episode rollouts: a victim drives an (optionally attacked) environment; records come out."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Callable

import gymnasium as gym
import numpy as np

from zodrive.attacks.victim import Victim
from zodrive.wrappers import AttackWrapper


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
    distance: float = 0.0      # [m] travelled along the road
    queries: int = 0           # attack queries over the episode
    attacked_steps: int = 0
    successes: int = 0         # steps where the attack met its goal (not already met)
    applicable: int = 0        # steps where the clean policy did not already meet it
    max_linf: float = 0.0
    action_counts: list[int] | None = None

    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        data["return"] = data.pop("return_")
        return data


def act(victim: Victim, obs: np.ndarray, space: gym.Space | None = None) -> Any:
    """The victim's deterministic action on one observation (not an attack query); a
    continuous action is kept inside the action space's box (default [-1, 1])."""
    out = victim.query(obs[None])
    action = victim.actions(out)[0]
    if victim.kind == "discrete":
        return int(action)
    if isinstance(space, gym.spaces.Box):
        return np.clip(action, space.low, space.high)
    return np.clip(action, -1.0, 1.0)


def clean_states(env: gym.Env, victim: Victim, seed: int, count: int) -> np.ndarray:
    """`count` observations the victim meets driving clean from `env.reset(seed=seed)`; an
    episode that ends is followed by one reset with seed `seed + states so far`."""
    obs, _ = env.reset(seed=seed)
    states = []
    for _ in range(count):
        states.append(obs)
        obs, _, terminated, truncated, _ = env.step(act(victim, obs, env.action_space))
        if terminated or truncated:
            obs, _ = env.reset(seed=seed + len(states))
    return np.stack(states)


def run_episode(
    env: gym.Env,
    victim: Victim,
    *,
    episode: int,
    seed: int,
    max_return: float | None,
    on_step: Callable[[dict[str, Any]], None] | None = None,
    policy: Victim | None = None,
) -> EpisodeRecord:
    """Roll out one episode from `env.reset(seed=seed)`.

    If `env` is wrapped in an `AttackWrapper`, the policy sees attacked observations and each
    step's attack stats go to `on_step`. `policy` (default: `victim`) chooses the actions.
    Driving metrics (speed, lanes, distance) are read on highway-env roads only; elsewhere
    they stay empty. `max_return` None: no percentage of the maximum.
    """
    policy = policy or victim
    wrapper = _find_attack(env)
    attacked = wrapper is not None
    obs, info = env.reset(seed=seed)
    road = hasattr(env.unwrapped, "vehicle") and hasattr(env.unwrapped, "road")
    ego = env.unwrapped.vehicle if road else None  # read for the driving metrics only; the policy sees `obs`
    start_x, lane = (float(ego.position[0]), ego.lane_index[2]) if road else (0.0, None)
    lane_changes = 0
    total, length, speeds, right = 0.0, 0, [], 0
    crashed = False
    queries = successes = applicable = 0
    max_linf = 0.0
    space = env.action_space
    counts = np.zeros(int(space.n), dtype=np.int64) if policy.kind == "discrete" and hasattr(space, "n") else None
    pending = info.get("attack") if attacked else None
    done = False
    while not done:
        action = act(policy, obs, space)
        if counts is not None:
            counts[action] += 1
        if pending is not None:
            queries += pending["queries"]
            successes += pending["success"]
            applicable += not pending["already"]
            max_linf = max(max_linf, pending["linf"])
            if on_step is not None:
                on_step({"episode": episode, "step": length, "action": _plain(action), **pending,
                         "wall_time": wrapper.last_wall_time})
        obs, reward, terminated, truncated, info = env.step(action)
        total += float(reward)
        length += 1
        speeds.append(float(info.get("speed", np.nan)))
        right += float(info.get("rewards", {}).get("right_lane_reward", 0.0)) >= 1.0
        crashed = bool(info.get("crashed", False))
        if road:
            ego = env.unwrapped.vehicle
            lane_changes += ego.lane_index[2] != lane
            lane = ego.lane_index[2]
        pending = info.get("attack") if attacked else None
        done = terminated or truncated
    return EpisodeRecord(
        episode=episode, seed=seed, return_=total,
        pct_of_max=100.0 * total / max_return if max_return else float("nan"),
        length=length, crashed=crashed, offroad=left_road(env, terminated, crashed), mean_speed=float(np.nanmean(speeds)) if road and speeds else float("nan"),
        right_lane_share=right / max(length, 1), lane_changes=int(lane_changes),
        distance=float(env.unwrapped.vehicle.position[0]) - start_x if road else 0.0, queries=queries,
        attacked_steps=length if attacked else 0, successes=int(successes),
        applicable=int(applicable), max_linf=max_linf,
        action_counts=counts.tolist() if counts is not None else None,
    )


def left_road(env: gym.Env, terminated: bool, crashed: bool) -> bool:
    """Whether the episode ended because the ego left the road (not a crash, not an arrival:
    intersection, merge and exit end on success too)."""
    ego = getattr(env.unwrapped, "vehicle", None)
    return bool(terminated and not crashed and ego is not None and not ego.on_road)


def _find_attack(env: gym.Env) -> AttackWrapper | None:
    while isinstance(env, gym.Env):
        if isinstance(env, AttackWrapper):
            return env
        if not isinstance(env, gym.Wrapper):
            return None
        env = env.env
    return None


def _plain(action: Any) -> Any:
    return action if isinstance(action, int) else [float(a) for a in np.asarray(action)]
