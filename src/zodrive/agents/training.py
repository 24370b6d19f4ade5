"""Train DQN / DDPG agents with stable-baselines3 from a recipe config."""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3 import DDPG, DQN
from stable_baselines3.common.callbacks import CheckpointCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.noise import NormalActionNoise, OrnsteinUhlenbeckActionNoise
from stable_baselines3.common.vec_env import DummyVecEnv

from zodrive.config import load_config
from zodrive.envs import action_kind, load_preset, make_env
from zodrive.errors import ZodriveError
from zodrive.runinfo import write_json, write_run_info

log = logging.getLogger(__name__)

ALGOS = {"dqn": DQN, "ddpg": DDPG}
KIND_OF_ALGO = {"dqn": "discrete", "ddpg": "continuous"}


def load_recipe(name: str, overrides: list[str] | None = None) -> dict[str, Any]:
    """A training recipe (algorithm, preset, step budget, hyperparameters)."""
    recipe = load_config(name, "recipes", overrides)
    algo = recipe.get("algo")
    if algo not in ALGOS:
        raise ZodriveError(f"recipe {name!r}: algo must be one of {sorted(ALGOS)}, not {algo!r}")
    steps = recipe.get("total_timesteps")
    if not isinstance(steps, int) or steps < 1:
        raise ZodriveError(f"recipe {name!r}: total_timesteps must be a positive integer")
    return recipe


def action_noise(spec: dict[str, Any] | None, n_actions: int):
    """SB3 action noise from `{type, sigma}`; DDPG explores with it."""
    if not spec:
        return None
    mean, sigma = np.zeros(n_actions), float(spec.get("sigma", 0.1)) * np.ones(n_actions)
    kind = spec.get("type", "normal")
    if kind == "normal":
        return NormalActionNoise(mean, sigma)
    if kind == "ornstein-uhlenbeck":
        return OrnsteinUhlenbeckActionNoise(mean, sigma)
    raise ZodriveError(f"unknown action noise type {kind!r} (normal, ornstein-uhlenbeck)")


def make_training_env(preset: dict[str, Any], seed: int, log_dir: Path) -> DummyVecEnv:
    """One monitored environment; its episode returns become the training curve."""

    def build():
        return Monitor(make_env(preset), filename=str(log_dir / "monitor"))

    venv = DummyVecEnv([build])
    venv.seed(seed)
    return venv


def train(
    recipe: dict[str, Any],
    out: Path,
    *,
    seed: int | None = None,
    preset_overrides: list[str] | None = None,
    progress_bar: bool = True,
    tensorboard: bool = False,
) -> Path:
    """Train per `recipe` into run folder `out`; returns the saved model path."""
    seed = int(recipe.get("seed", 0) if seed is None else seed)
    algo = recipe["algo"]
    preset = load_preset(recipe.get("preset", KIND_OF_ALGO[algo]), preset_overrides)
    if action_kind(preset) != KIND_OF_ALGO[algo]:
        raise ZodriveError(f"{algo} needs a {KIND_OF_ALGO[algo]} preset, not {preset['name']!r}")
    out.mkdir(parents=True, exist_ok=True)
    write_run_info(out, {"recipe": recipe, "preset": preset}, seed)
    torch.set_num_threads(1)  # small MLPs: one thread is fastest and lets runs share cores

    env = make_training_env(preset, seed, out)
    kwargs = dict(recipe.get("hyperparameters") or {})
    if algo == "ddpg":
        kwargs["action_noise"] = action_noise(recipe.get("action_noise"), env.action_space.shape[0])
    model = ALGOS[algo](
        "MlpPolicy",
        env,
        seed=seed,
        device="cpu",
        verbose=0,
        tensorboard_log=str(out / "tb") if tensorboard else None,
        **kwargs,
    )
    model.set_logger(configure(str(out), ["csv"] + (["tensorboard"] if tensorboard else [])))
    every = int(recipe.get("checkpoint_every", 0) or 0)
    callback = CheckpointCallback(every, str(out / "checkpoints"), name_prefix=algo) if every else None
    start = time.perf_counter()
    model.learn(
        total_timesteps=int(recipe["total_timesteps"]),
        callback=callback,
        progress_bar=progress_bar,
        log_interval=1 if algo == "ddpg" else 4,
    )
    wall = time.perf_counter() - start
    path = out / "model.zip"
    model.save(path)
    write_json(
        out / "train.json",
        {"algo": algo, "total_timesteps": int(recipe["total_timesteps"]), "seed": seed,
         "wall_time_s": round(wall, 1), "steps_per_s": round(recipe["total_timesteps"] / wall, 1)},
    )
    env.close()
    log.info("trained %s for %d steps in %.0f s", algo, recipe["total_timesteps"], wall)
    return path
