"""Environment presets: resolve a preset config, build its gymnasium environment, and read
what attacks and policies need to know about it (`scenario`).

A preset names a gymnasium id and, for highway-env scenarios, the config passed to it
(`highway:`). `scenario(preset)` builds the environment once and reads its facts from the
environment itself (spaces, observation features, meta-action names), so a preset that
gives only part of highway-env's config is still described exactly. `gym_preset(ID)` makes a
preset for any gymnasium environment with a Box observation.
"""

from __future__ import annotations

import functools
import json
import math
import os
from dataclasses import dataclass, field
from typing import Any, Literal

import gymnasium as gym
import numpy as np

from zodrive.config import available, check_keys, config_root, load_config, read_text
from zodrive.envs.traffic import KeepTraffic, restore_defaults
from zodrive.errors import ZodriveError, cause

ActionKind = Literal["discrete", "continuous"]
"""The same type as `zodrive.attacks.victim.ActionKind` (a room on this floor: not imported)."""

ENV_ID = "zodrive/highway-v0"
ACTION_NAMES = ("LANE_LEFT", "IDLE", "LANE_RIGHT", "FASTER", "SLOWER")  # highway-v0's DiscreteMetaAction
CONTINUOUS_NAMES = ("acceleration", "steering")

PRESET_KEYS = {"env_id", "max_episode_steps", "highway", "name", "env_kwargs", "obs_bounds"}
OBSERVATION_TYPES = ("Kinematics", "FastKinematics", "ExitObservation", "OccupancyGrid", "GrayscaleObservation",
                     "TimeToCollision", "LidarObservation")
"""highway-env's observers whose observation is one Box (zodrive attacks Box observations)."""


@dataclass(frozen=True)
class Scenario:
    """What a preset's environment is, as attacks, victims and reports see it."""

    name: str
    kind: ActionKind                   # discrete | continuous
    obs_shape: tuple[int, ...]
    features: tuple[str, ...]          # names along `feature_axis` of the observation (() if unnamed)
    bounds: tuple[Any, Any]            # range of a clean observation value: two numbers, or per dimension
    #                                    (the space's box, flattened) where it is not one range
    n_actions: int                     # discrete actions, or action dimensions
    action_names: tuple[str, ...]      # meta-action names by index, or the action's dimensions
    action_low: tuple[float, ...]      # continuous: the action space's box (() for discrete)
    action_high: tuple[float, ...]
    road: bool                         # a highway-env road: driving metrics and the driver baselines
    max_return: float | None           # the return of a perfect episode, where it is known
    feature_ranges: dict[str, tuple[float, float]] = field(default_factory=dict)  # what a normalized 1 means
    relative: bool = False             # highway-env rows relative to the ego (not absolute positions)
    normalized: bool = False           # highway-env rows normalized by `feature_ranges`
    lanes: int | None = None           # lanes of a highway-env road
    policy_frequency: float | None = None  # decisions per second of a highway-env scenario (its live config)
    space_low: tuple[float, ...] = ()  # the observation space's declared box, flattened
    space_high: tuple[float, ...] = ()
    feature_axis: int = -1             # the axis the features are named along (OccupancyGrid: the first)

    def attack_context(self) -> dict[str, Any]:
        """What an attack needs to know about these observations and actions (`AttackSpec.build`)."""
        return {"features": self.features, "bounds": self.bounds, "feature_axis": self.feature_axis,
                "n_actions": self.n_actions,
                "action_names": self.action_names,
                "action_bounds": (self.action_low, self.action_high) if self.kind == "continuous" else None}


def _within_declared(name: str, given: tuple[float, float], space: gym.spaces.Box) -> tuple[Any, Any]:
    """`obs_bounds` met with the space's declared box, value by value: the declared range where it is finite
    and narrower (CartPole's x in [-4.8, 4.8]), `given` where the environment declares none (its speeds). A
    range that changes no value is an ignored option, and refused."""
    low, high = space.low.astype(np.float64).ravel(), space.high.astype(np.float64).ravel()
    new_low, new_high = np.maximum(low, given[0]), np.minimum(high, given[1])
    if np.array_equal(new_low, low) and np.array_equal(new_high, high):
        raise ZodriveError(f"{name}: obs_bounds [{given[0]:g}, {given[1]:g}] change nothing: every value's declared "
                           "range is already inside them (drop --obs-bounds)")
    if np.any(new_low >= new_high):
        i = int(np.flatnonzero(new_low >= new_high)[0])
        raise ZodriveError(f"{name}: obs_bounds [{given[0]:g}, {given[1]:g}] leave value {i} no range (declared "
                           f"[{low[i]:g}, {high[i]:g}])")
    if np.all(new_low == new_low[0]) and np.all(new_high == new_high[0]):
        return float(new_low[0]), float(new_high[0])
    return tuple(map(float, new_low)), tuple(map(float, new_high))


def register() -> None:
    """Register zodrive's highway-env scenarios with gymnasium (idempotent)."""
    if ENV_ID not in gym.registry:
        import highway_env  # noqa: F401  (registers highway-v0 and friends)

        from zodrive.envs.highway import FAST_ENVS

        for env_id, (cls, _) in FAST_ENVS.items():
            gym.register(id=env_id, entry_point=f"zodrive.envs.highway:{cls}")


def _env_class(env_id: str) -> type[Any] | None:
    register()
    try:
        # a callable entry point fails here as an unknown id does: no class to read defaults from
        creator = gym.envs.registration.load_env_creator(gym.spec(env_id).entry_point)  # type: ignore[arg-type]
    except Exception:  # noqa: BLE001 - an id gymnasium does not know is reported by make_env
        return None
    return creator if isinstance(creator, type) else None


def is_highway(env_id: str) -> bool:
    """Whether `env_id` is a highway-env scenario (configured through `highway:`)."""
    from highway_env.envs.common.abstract import AbstractEnv

    cls = _env_class(env_id)
    return cls is not None and issubclass(cls, AbstractEnv)


def load_preset(name: str, overrides: list[str] | None = None) -> dict[str, Any]:
    """The resolved preset config (file, `base:` chain and overrides deep-merged)."""
    config = load_config(name, "presets", overrides)
    validate_preset(config, name)
    config["name"] = config.get("name", name)
    return config


def gym_preset(env_id: str, overrides: list[str] | None = None, obs_bounds: tuple[float, float] | None = None
               ) -> dict[str, Any]:
    """A preset for any registered gymnasium environment (`--env-id`); highway-env ids get
    their own default config, anything else its constructor's defaults (`env_kwargs`)."""
    from zodrive.config import deep_merge, parse_override

    register()
    if env_id not in gym.registry:
        import difflib

        close = difflib.get_close_matches(env_id, list(gym.registry), n=1)
        raise ZodriveError(f"unknown gymnasium environment {env_id!r}"
                           + (f"; did you mean {close[0]!r}?" if close else ""))
    config: dict[str, Any] = {"env_id": env_id, "max_episode_steps": gym.spec(env_id).max_episode_steps}
    config["highway" if is_highway(env_id) else "env_kwargs"] = {}
    if obs_bounds is not None:
        config["obs_bounds"] = [float(obs_bounds[0]), float(obs_bounds[1])]
    for text in overrides or []:
        config = deep_merge(config, parse_override(text))
    validate_preset(config, env_id)
    config["name"] = env_id
    return config


def preset_for_env(env_id: str, env_kwargs: dict[str, Any] | None = None,
                   overrides: list[str] | None = None) -> dict[str, Any]:
    """The scenario a model trained on `env_id` with `env_kwargs` drives: the shipped preset of that
    highway-env id (zodrive's exact observer, same config) with the model's `config` merged in, or
    a preset of the gymnasium id itself."""
    from zodrive.config import deep_merge

    kwargs = dict(env_kwargs or {})
    matches = [name for name in preset_names()
               if load_config(name, "presets").get("env_id", ENV_ID).removeprefix("zodrive/") == env_id]
    if not matches:
        config = gym_preset(env_id, overrides)
        if kwargs:
            key = "highway" if "highway" in config else "env_kwargs"
            config[key] = deep_merge(config[key], kwargs.get("config", kwargs) if key == "highway" else kwargs)
            validate_preset(config, env_id)
        return config
    config = load_preset(sorted(matches, key=len)[0], overrides)
    extra = set(kwargs) - {"config"}
    if extra:
        raise ZodriveError(f"env_kwargs {sorted(extra)} of a model trained on {env_id}: zodrive passes highway-env "
                           "only its `config`; run it with --env-id and --env-set")
    if kwargs.get("config"):
        config["highway"] = deep_merge(config.get("highway") or {}, kwargs["config"])
        validate_preset(config, env_id)
    return config


DISPLAY_KEYS = frozenset({"screen_width", "screen_height", "centering_position", "scaling", "show_trajectories",
                          "render_agent", "offscreen_rendering", "real_time_rendering", "manual_control",
                          "render_mode"})
"""highway-env settings that change only what is drawn, never what the policy observes or the episode."""


def differences_from_training(config: dict[str, Any], env_id: str, env_kwargs: dict[str, Any]) -> list[str]:
    """Where the preset `config` differs from what a model says it was trained on (`env_id` with
    `env_kwargs`): another environment id (`merge-v1` is not `merge-v0`), or a setting the model
    states with another value than the preset runs (the preset's own, else the environment's
    default). One short phrase per difference; empty when the preset is where the model drove."""
    from zodrive.config import deep_merge

    ran = str(config.get("env_id", ENV_ID)).removeprefix("zodrive/")
    if ran != env_id:
        return [f"environment {ran}, not {env_id}"]
    if "highway" in config:
        cls = _env_class(config.get("env_id", ENV_ID))
        runs = deep_merge(cls.default_config() if cls is not None else {}, config["highway"])
        stated = env_kwargs.get("config") or {}
    else:
        runs, stated = config.get("env_kwargs") or {}, env_kwargs
    found: list[str] = []

    def walk(want: Any, have: Any, path: str) -> None:
        if isinstance(want, dict) and isinstance(have, dict):
            for key, value in want.items():
                if path or key not in DISPLAY_KEYS:
                    walk(value, have.get(key, _MISSING), f"{path}.{key}" if path else str(key))
        elif have is _MISSING or not _same(_observer(path, want), _observer(path, have)):
            found.append(f"{path} {'unset' if have is _MISSING else _short(have)}, not {_short(want)}")

    walk(stated, runs, "")
    return found


_MISSING = object()


def _observer(path: str, value: Any) -> Any:
    """zodrive's FastKinematics observer gives Kinematics' observation exactly: the same setting."""
    return "Kinematics" if path == "observation.type" and value == "FastKinematics" else value


def changed_settings(env_id: str, config: dict[str, Any]) -> dict[str, Any]:
    """The settings of a live highway-env `config` that differ from `env_id`'s defaults (display aside)."""
    cls = _env_class(env_id)
    defaults = cls.default_config() if cls is not None else {}
    return {key: value for key, value in config.items()
            if key not in DISPLAY_KEYS and (key not in defaults or not _same(defaults[key], value))}


def _as_data(value: Any) -> Any:
    """A value as YAML and JSON give it: tuples and numpy arrays as lists, so that (4, 5) equals [4, 5]."""
    return json.loads(json.dumps(value, default=lambda x: x.tolist() if hasattr(x, "tolist") else str(x)))


def _same(a: Any, b: Any) -> bool:
    return _as_data(a) == _as_data(b)


def _short(value: Any) -> str:
    text = json.dumps(_as_data(value))
    return text if len(text) <= 40 else text[:37] + "..."


def validate_preset(config: dict[str, Any], name: str) -> None:
    """Catch config mistakes up front, before highway-env turns them into tracebacks."""
    check_keys(config, PRESET_KEYS, f"preset {name!r}")
    env_id = config.get("env_id", ENV_ID)
    if not isinstance(env_id, str):
        raise ZodriveError(f"preset {name!r}: env_id must be a gymnasium id")
    steps = config.get("max_episode_steps")
    if steps is not None and (not isinstance(steps, int) or isinstance(steps, bool) or steps < 1):
        raise ZodriveError(f"preset {name!r}: max_episode_steps must be a positive integer "
                           "(or null: the env's own end)")
    bounds = config.get("obs_bounds")
    if bounds is not None and not (isinstance(bounds, list) and len(bounds) == 2
                                   and all(isinstance(b, (int, float)) and not isinstance(b, bool) for b in bounds)
                                   and bounds[0] < bounds[1]):
        raise ZodriveError(f"preset {name!r}: obs_bounds must be [low, high] with low < high")
    hw = config.get("highway")
    if hw is None:
        if is_highway(env_id):
            raise ZodriveError(f"preset {name!r}: {env_id} is a highway-env scenario and needs a 'highway' mapping")
        if not isinstance(config.get("env_kwargs", {}), dict):
            raise ZodriveError(f"preset {name!r}: env_kwargs must be a mapping")
        return
    if not isinstance(hw, dict):
        raise ZodriveError(f"preset {name!r}: 'highway' must be a mapping")
    if not is_highway(env_id):
        raise ZodriveError(f"preset {name!r}: {env_id} is not a highway-env scenario; give its options as env_kwargs")
    from zodrive.envs.schema import validate_highway

    cls = _env_class(env_id)
    validate_highway(hw, cls.default_config() if cls is not None else {}, f"preset {name!r}")
    obs = hw.get("observation", {})
    if "type" in obs and obs["type"] not in OBSERVATION_TYPES:
        raise ZodriveError(f"preset {name!r}: observation.type must be one of {', '.join(OBSERVATION_TYPES)} "
                           "(highway-env's observers with one Box observation)")
    action = hw.get("action", {}).get("type") if isinstance(hw.get("action"), dict) else None
    if action is not None and action not in ("DiscreteMetaAction", "ContinuousAction"):
        raise ZodriveError(f"preset {name!r}: action.type must be DiscreteMetaAction or ContinuousAction")


def _key(config: dict[str, Any]) -> str:
    return json.dumps(config, sort_keys=True, default=str)


def scenario(config: dict[str, Any]) -> Scenario:
    """The facts of a preset's environment (built once per preset and process)."""
    return _scenario(_key(config))


@functools.lru_cache(maxsize=32)
def _scenario(key: str) -> Scenario:
    config = json.loads(key)
    env = make_env(config)
    try:
        return _read_scenario(config, env)
    finally:
        env.close()


def _read_scenario(config: dict[str, Any], env: gym.Env) -> Scenario:
    name = config.get("name", config.get("env_id", ENV_ID))
    space, actions = env.observation_space, env.action_space
    if not isinstance(space, gym.spaces.Box):
        raise ZodriveError(f"{name}: zodrive attacks Box observations, not {type(space).__name__}")
    core: Any = env.unwrapped  # highway-env's AbstractEnv where `road` (untyped)
    road = hasattr(core, "road") and hasattr(core, "observation_type")
    features: tuple[str, ...] = ()
    bounds: tuple[Any, Any] = (float("-inf"), float("inf"))
    axis = -1
    observer: Any = getattr(core, "observation_type", None)
    kinematic = road and hasattr(observer, "features") and hasattr(observer, "normalize")
    if kinematic:
        env.reset(seed=0)  # highway-env fills in its default feature ranges at the first observation
        features = tuple(observer.features)
        if space.shape and space.shape[-1] != len(features) and space.shape[0] == len(features):
            axis = 0  # OccupancyGrid: one (H, W) grid per feature
        if observer.normalize and getattr(observer, "clip", False):
            bounds = (-1.0, 1.0)  # highway-env declares (-inf, inf) for a normalized, clipped observation
    else:
        low, high = np.unique(space.low), np.unique(space.high)
        if len(low) == 1 and len(high) == 1:
            bounds = (float(low[0]), float(high[0]))
        else:  # a box per dimension (Pendulum: cos, sin in [-1, 1], the speed in [-8, 8])
            bounds = (tuple(map(float, space.low.ravel())), tuple(map(float, space.high.ravel())))
    if config.get("obs_bounds") is not None:
        bounds = _within_declared(name, (float(config["obs_bounds"][0]), float(config["obs_bounds"][1])), space)
    kind: ActionKind
    if isinstance(actions, gym.spaces.Discrete):
        kind, n = "discrete", int(actions.n)
        names = tuple(core.action_type.actions[i] for i in range(n)) if road and hasattr(
            getattr(core, "action_type", None), "actions") else tuple(str(i) for i in range(n))
        low_a: tuple[float, ...] = ()
        high_a: tuple[float, ...] = ()
    elif isinstance(actions, gym.spaces.Box) and len(actions.shape) == 1:
        kind, n = "continuous", int(actions.shape[0])
        action_type: Any = getattr(core, "action_type", None)
        if road and hasattr(action_type, "longitudinal"):
            names = tuple(d for d, on in zip(CONTINUOUS_NAMES, (action_type.longitudinal, action_type.lateral)) if on)
        else:
            names = tuple(f"a{i}" for i in range(n))
        low_a, high_a = tuple(map(float, actions.low)), tuple(map(float, actions.high))
    else:
        raise ZodriveError(f"{name}: zodrive attacks policies with Discrete or 1-D Box actions, not {actions}")
    observed: dict[str, Any] = {}
    if kinematic:
        observed = {"feature_ranges": {k: (float(v[0]), float(v[1]))
                                       for k, v in (observer.features_range or {}).items()},
                    "relative": not observer.absolute, "normalized": bool(observer.normalize),
                    "lanes": core.config.get("lanes_count") or _lanes_at_start(core),
                    "policy_frequency": float(core.config["policy_frequency"])}
    return Scenario(name=name, kind=kind, obs_shape=tuple(space.shape), features=features, bounds=bounds,
                    feature_axis=axis, n_actions=n, action_names=names, action_low=low_a, action_high=high_a, road=road,
                    max_return=_max_return(config, core),
                    space_low=tuple(map(float, np.asarray(space.low).ravel())),
                    space_high=tuple(map(float, np.asarray(space.high).ravel())), **observed)


def _lanes_at_start(core: Any) -> int | None:
    """Lanes of the road the ego starts on, where the preset does not set `lanes_count` (merge:
    the main road's two; the on-ramp joins it from the right and ends)."""
    vehicle = getattr(core, "vehicle", None)
    if vehicle is None or getattr(vehicle, "lane_index", None) is None:
        return None
    return len(core.road.network.all_side_lanes(vehicle.lane_index))


def _max_return(config: dict[str, Any], core: Any) -> float | None:
    """Steps of a full episode when every step can earn at most 1 (normalized highway-env reward)."""
    if config.get("max_episode_steps") and config.get("env_id", ENV_ID) == ENV_ID:
        return float(config["max_episode_steps"])  # the paper's preset: 450 decisions
    cfg = getattr(core, "config", None)
    if not isinstance(cfg, dict) or not cfg.get("normalize_reward") or not cfg.get("duration"):
        return None
    steps = math.ceil(cfg["duration"] * cfg["policy_frequency"])
    return float(min(steps, config["max_episode_steps"]) if config.get("max_episode_steps") else steps)


def action_kind(config: dict[str, Any]) -> ActionKind:
    """`discrete` or `continuous`, from the preset's environment."""
    hw = config.get("highway")
    if isinstance(hw, dict) and hw.get("action", {}).get("type"):  # no environment needed
        return "discrete" if hw["action"]["type"] == "DiscreteMetaAction" else "continuous"
    return scenario(config).kind


def observation_shape(config: dict[str, Any]) -> tuple[int, ...]:
    return scenario(config).obs_shape


def feature_names(config: dict[str, Any]) -> list[str]:
    return list(scenario(config).features)


def observation_bounds(config: dict[str, Any]) -> tuple[Any, Any]:
    """The range of a clean observation value: [-1, 1] when highway-env normalizes and clips,
    the observation space's box (one interval, or per dimension), `obs_bounds` when the preset says so."""
    return scenario(config).bounds


def n_actions(config: dict[str, Any]) -> int:
    return scenario(config).n_actions


def action_names(config: dict[str, Any]) -> tuple[str, ...]:
    return scenario(config).action_names


def attack_context(config: dict[str, Any]) -> dict[str, Any]:
    """What an attack needs to know about the preset's observations and actions."""
    return scenario(config).attack_context()


def scenario_of_env(env: gym.Env) -> Scenario:
    """The facts of an environment built elsewhere (a user's own): its observation's features
    and box, its actions. A highway-env environment is reset once, with seed 0, since
    highway-env fills in its feature ranges at the first observation."""
    name = env.spec.id if env.spec is not None else type(env.unwrapped).__name__
    return _read_scenario({"name": name, "env_id": name}, env)


def _shapes_as_tuples(value: Any, key: str = "") -> Any:
    """YAML and --env-set give lists; highway-env wants a tuple where it takes a shape
    (`observation_shape` of GrayscaleObservation, ...)."""
    if isinstance(value, dict):
        return {k: _shapes_as_tuples(v, k) for k, v in value.items()}
    if isinstance(value, list) and key.endswith("_shape"):
        return tuple(value)
    return value


def make_env(config: dict[str, Any], render_mode: str | None = None) -> gym.Env:
    """Build the environment a preset describes, capped at `max_episode_steps` decisions."""
    register()
    if render_mode == "rgb_array" and os.environ.get("SDL_VIDEODRIVER") == "dummy":
        os.environ["SDL_VIDEODRIVER"] = "offscreen"  # "dummy" makes highway-env draw black frames
    image = (config.get("highway") or {}).get("observation", {}).get("type") == "GrayscaleObservation"
    if (render_mode is not None or image) and not os.path.isdir(os.environ.get("XDG_RUNTIME_DIR", "")):
        import tempfile  # SDL prints an error line to stderr without a runtime folder

        os.environ["XDG_RUNTIME_DIR"] = tempfile.mkdtemp(prefix="zodrive-xdg-")
    env_id = config.get("env_id", ENV_ID)
    kwargs = {"config": _shapes_as_tuples(config["highway"])} if config.get("highway") is not None \
        else dict(config.get("env_kwargs") or {})
    restore_defaults()  # highway-env's constructor resets the env once already
    try:
        env = gym.make(env_id, render_mode=render_mode, max_episode_steps=config.get("max_episode_steps"), **kwargs)
    except gym.error.Error as exc:
        raise ZodriveError(f"preset {config.get('name', env_id)!r}: {exc}") from None
    except (TypeError, ValueError, KeyError, AssertionError) as exc:
        raise ZodriveError(f"preset {config.get('name', '?')!r} is not a valid config for {env_id}: "
                           f"{cause(exc)}") from exc
    if "other_vehicles_type" in (getattr(env.unwrapped, "config", None) or {}):  # highway-env's traffic
        env = KeepTraffic(env)
    return env


def preset_names() -> list[str]:
    return available("presets")


def preset_summary(name: str) -> str:
    """The first sentence of a shipped preset file's leading comment: what it is, in one line."""
    path = config_root() / "presets" / f"{name}.yaml"
    lines = []
    for line in read_text(path, "preset file").splitlines():
        if not line.startswith("#"):
            break
        lines.append(line.lstrip("# ").strip())
    text = " ".join(lines)
    return text.split(". ")[0].rstrip(".")
