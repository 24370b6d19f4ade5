"""Load SB3 DQN/DDPG zips and check that they fit a preset, with one-line errors."""

from __future__ import annotations

import warnings
import zipfile
from pathlib import Path
from typing import Any

from gymnasium import spaces
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.save_util import load_from_zip_file

from zodrive.agents.training import ALGOS, KIND_OF_ALGO
from zodrive.envs import action_kind, observation_shape
from zodrive.errors import ZodriveError

POLICY_TO_ALGO = {"DQNPolicy": "dqn", "TD3Policy": "ddpg"}  # SB3's DDPG uses TD3Policy


def model_file(path: str | Path) -> Path:
    """`path` itself, or `path/model.zip` for a model folder."""
    path = Path(path)
    if path.is_dir():
        path = path / "model.zip"
    if not path.is_file():
        raise ZodriveError(f"model file not found: {path}")
    return path


def inspect_model(path: Path) -> dict[str, Any]:
    """Algorithm and spaces stored in an SB3 zip, without building the model."""
    if not zipfile.is_zipfile(path):
        raise ZodriveError(f"{path} is not a stable-baselines3 model (not a zip file)")
    try:
        data, _, _ = load_from_zip_file(path, device="cpu", load_data=True)
    except Exception as exc:  # SB3 raises many types for damaged archives
        raise ZodriveError(f"{path} is corrupt or not a stable-baselines3 model ({type(exc).__name__})") from exc
    if not data or "policy_class" not in data:
        raise ZodriveError(f"{path} is not a stable-baselines3 model (no policy data)")
    policy = getattr(data["policy_class"], "__name__", str(data["policy_class"]))
    algo = POLICY_TO_ALGO.get(policy)
    if algo is None:
        raise ZodriveError(f"{path}: unsupported policy {policy} (zodrive loads DQN and DDPG)")
    return {"algo": algo, "observation_space": data.get("observation_space"),
            "action_space": data.get("action_space")}


def check_fits(info: dict[str, Any], preset: dict[str, Any], path: Path) -> None:
    """Raise if the model's algorithm or spaces do not match the preset."""
    kind = action_kind(preset)
    if KIND_OF_ALGO[info["algo"]] != kind:
        raise ZodriveError(
            f"{path} is a {info['algo'].upper()} model; preset {preset['name']!r} has "
            f"{kind} actions (use a {'DQN' if kind == 'discrete' else 'DDPG'} model)"
        )
    obs_space = info["observation_space"]
    want = observation_shape(preset)
    if not isinstance(obs_space, spaces.Box) or tuple(obs_space.shape) != want:
        got = getattr(obs_space, "shape", obs_space)
        raise ZodriveError(f"{path} expects observations of shape {got}; preset gives {want}")
    act_space = info["action_space"]
    n_actions = 5 if kind == "discrete" else 2
    size = act_space.n if isinstance(act_space, spaces.Discrete) else act_space.shape[0]
    if size != n_actions:
        raise ZodriveError(f"{path} has {size} actions; preset {preset['name']!r} has {n_actions}")


def load_model(path: str | Path, preset: dict[str, Any] | None = None) -> BaseAlgorithm:
    """Load a DQN/DDPG zip on the CPU; with `preset`, check that it fits first."""
    file = model_file(path)
    info = inspect_model(file)
    if preset is not None:
        check_fits(info, preset, file)
    try:
        with warnings.catch_warnings():  # SB3 warns that saved n-step settings are not re-applied
            warnings.filterwarnings("ignore", message=".*n_steps.*ignored.*")
            return ALGOS[info["algo"]].load(file, device="cpu")
    except Exception as exc:
        raise ZodriveError(f"{file} could not be loaded ({type(exc).__name__}: {exc})") from exc


def model_algo(path: str | Path) -> str:
    """`dqn` or `ddpg` for a model file, read from its stored policy class."""
    return inspect_model(model_file(path))["algo"]
