"""Environment presets: resolve a preset config and build the gymnasium environment."""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym

from zodrive.config import available, check_keys, load_config
from zodrive.errors import ZodriveError

ENV_ID = "zodrive/highway-v0"
ACTION_NAMES = ("LANE_LEFT", "IDLE", "LANE_RIGHT", "FASTER", "SLOWER")


PRESET_KEYS = {"env_id", "max_episode_steps", "highway", "name"}


def highway_keys() -> set[str]:
    """The configuration keys highway-env's `highway-v0` knows."""
    from highway_env.envs.highway_env import HighwayEnv

    return set(HighwayEnv.default_config())


def register() -> None:
    """Register `zodrive/highway-v0` with gymnasium (idempotent)."""
    if ENV_ID not in gym.registry:
        import highway_env  # noqa: F401  (registers highway-v0 and friends)

        gym.register(id=ENV_ID, entry_point="zodrive.envs.highway:ZodriveHighwayEnv")


def load_preset(name: str, overrides: list[str] | None = None) -> dict[str, Any]:
    """The resolved preset config (file, `base:` chain and overrides deep-merged)."""
    config = load_config(name, "presets", overrides)
    validate_preset(config, name)
    config["name"] = config.get("name", name)
    return config


def validate_preset(config: dict[str, Any], name: str) -> None:
    """Catch config mistakes up front, before highway-env turns them into tracebacks."""
    hw = config.get("highway")
    if not isinstance(hw, dict):
        raise ZodriveError(f"preset {name!r} has no 'highway' mapping")
    check_keys(config, PRESET_KEYS, f"preset {name!r}")
    check_keys(hw, highway_keys(), f"preset {name!r}", "highway.")
    steps = config.get("max_episode_steps")
    if not isinstance(steps, int) or steps < 1:
        raise ZodriveError(f"preset {name!r}: max_episode_steps must be a positive integer")
    obs = hw.get("observation", {})
    if obs.get("type") not in ("Kinematics", "FastKinematics"):
        raise ZodriveError(
            f"preset {name!r}: observation.type must be Kinematics or FastKinematics"
        )
    action = hw.get("action", {}).get("type")
    if action not in ("DiscreteMetaAction", "ContinuousAction"):
        raise ZodriveError(
            f"preset {name!r}: action.type must be DiscreteMetaAction or ContinuousAction"
        )
    for key, least in (("vehicles_count", 0), ("lanes_count", 1), ("simulation_frequency", 1), ("policy_frequency", 1)):
        value = hw.get(key)
        if value is not None and (not isinstance(value, int) or isinstance(value, bool) or value < least):
            raise ZodriveError(f"preset {name!r}: highway.{key} must be an integer >= {least}")


def action_kind(config: dict[str, Any]) -> str:
    """`discrete` or `continuous`, from the preset's action type."""
    return "discrete" if config["highway"]["action"]["type"] == "DiscreteMetaAction" else "continuous"


def observation_shape(config: dict[str, Any]) -> tuple[int, int]:
    """(vehicles, features) of the preset's observation."""
    obs = config["highway"]["observation"]
    return int(obs.get("vehicles_count", 5)), len(obs.get("features", ["presence", "x", "y", "vx", "vy"]))


def feature_names(config: dict[str, Any]) -> list[str]:
    return list(config["highway"]["observation"].get("features", ["presence", "x", "y", "vx", "vy"]))


def observation_bounds(config: dict[str, Any]) -> tuple[float, float]:
    """The range of a clean observation value: [-1, 1] when the preset normalizes and clips
    (highway-env's Kinematics), otherwise unbounded. highway-env declares its observation
    space as (-inf, inf) either way, so the preset, not the space, is the source."""
    obs = config["highway"]["observation"]
    if obs.get("normalize", True) and obs.get("clip", True):
        return -1.0, 1.0
    return float("-inf"), float("inf")


def n_actions(config: dict[str, Any]) -> int:
    """Outputs of a policy for the preset: 5 meta-actions, or [acceleration, steering]."""
    action = config["highway"]["action"]
    if action_kind(config) == "discrete":
        return len(ACTION_NAMES)
    return int(action.get("longitudinal", True)) + int(action.get("lateral", True))


def attack_context(config: dict[str, Any]) -> dict[str, Any]:
    """What an attack needs to know about the preset's observations and actions."""
    return {"features": tuple(feature_names(config)), "bounds": observation_bounds(config),
            "n_actions": n_actions(config)}


def make_env(config: dict[str, Any], render_mode: str | None = None) -> gym.Env:
    """Build the environment a preset describes, capped at `max_episode_steps` decisions."""
    register()
    if render_mode == "rgb_array" and os.environ.get("SDL_VIDEODRIVER") == "dummy":
        os.environ["SDL_VIDEODRIVER"] = "offscreen"  # "dummy" makes highway-env draw black frames
    try:
        env = gym.make(
            config.get("env_id", ENV_ID),
            config=config["highway"],
            render_mode=render_mode,
            max_episode_steps=config["max_episode_steps"],
        )
    except (TypeError, ValueError, KeyError) as exc:
        raise ZodriveError(f"preset {config.get('name', '?')!r} is not a valid highway-env config: {exc}") from exc
    return env


def preset_names() -> list[str]:
    return available("presets")
