"""Train DQN / DDPG agents with stable-baselines3 from a recipe config."""

from __future__ import annotations

import inspect
import json
import logging
import shutil
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from stable_baselines3.common.callbacks import CheckpointCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.noise import NormalActionNoise, OrnsteinUhlenbeckActionNoise
from stable_baselines3.common.vec_env import DummyVecEnv

from zodrive.compute import one_torch_thread
from zodrive.config import check_keys, load_config, read_yaml
from zodrive.envs import action_kind, load_preset, make_env
from zodrive.errors import ZodriveError, cause
from zodrive.policies.loading import ALGOS
from zodrive.runinfo import command_line, read_json, write_atomic, write_json, write_run_info
from zodrive.signing import signature

log = logging.getLogger(__name__)

KIND_OF_ALGO = {"dqn": "discrete", "ddpg": "continuous", "td3": "continuous"}
ACTOR_CRITIC = ("ddpg", "td3")  # deterministic actor + action noise; their zips load alike
RECIPE_KEYS = {"algo", "preset", "total_timesteps", "seed", "hyperparameters", "action_noise", "checkpoint_every",
               "double_q", "guide", "init", "calibrate"}
DEMO_SEEDS = 20000   # the init actor's episodes of a run with seed s use seeds 20000 + 1000 s + i (not tuning/eval)
CALIBRATE_KEYS = {"episodes": 30, "td_steps": 10000}  # recipe `calibrate:` defaults: collect, then critic-only TD
GUIDE_KEYS = {"name", "imitation", "error"}  # DDPG / TD3: TD3+BC's imitation term
GUIDES = ("rules", "init")  # the continuous rules, or the recipe's init actor kept frozen
REMOVED = {"guide": "results/driver-sweep/ and results/finetune/", "init": "results/finetune/",
           "calibrate": "results/finetune/"}
"""Options a dqn recipe no longer has (issue 45: guided exploration, DQfD's margin loss and pre-training,
fine-tuning from the clone; none was shipped), and where their measurements live (docs/drivers.md,
section "Removed options")."""
REMOVED_RECIPES = ("dqn-guided", "dqn-dqfd", "dqn-pretrained", "dqn-finetune")


def check_removed(recipe: dict[str, Any], context: str) -> None:
    """A dqn recipe that sets a removed option is a one-line error (an ignored option would be silent)."""
    gone = [key for key in REMOVED if recipe.get("algo") == "dqn" and recipe.get(key) is not None]
    if gone:
        where = "; ".join(f"{key} (its measurement: {REMOVED[key]})" for key in gone)
        raise ZodriveError(f"{context}: {where}: removed from zodrive for dqn recipes "
                           "(docs/drivers.md, section \"Removed options\")")


def algorithm_class(recipe: dict[str, Any]):
    """The SB3 class a recipe trains: DQN (optionally with the Double-DQN target), DDPG or TD3
    (GuidedDDPG / GuidedTD3 with a guide or an init actor)."""
    if recipe.get("double_q"):
        if recipe["algo"] != "dqn":
            raise ZodriveError("double_q applies to dqn recipes only")
        from zodrive.training.dqn_variants import DoubleDQN

        return DoubleDQN
    if recipe["algo"] in ACTOR_CRITIC and (recipe.get("guide") or recipe.get("init")):
        # an actor-critic started from a clone needs GuidedTD3's critic-only updates even without a guide
        from zodrive.training.actor_critic_variants import GuidedDDPG, GuidedTD3

        return {"ddpg": GuidedDDPG, "td3": GuidedTD3}[recipe["algo"]]
    return ALGOS[recipe["algo"]]


def load_recipe(name: str, overrides: list[str] | None = None) -> dict[str, Any]:
    """A training recipe (algorithm, preset, step budget, hyperparameters)."""
    if name in REMOVED_RECIPES:
        raise ZodriveError(f"recipe {name!r} was removed from zodrive (issue 45; its measurement: "
                           "results/driver-sweep/ and results/finetune/; docs/drivers.md, section \"Removed options\")")
    recipe = load_config(name, "recipes", overrides)
    algo = recipe.get("algo")
    if algo not in ALGOS:
        raise ZodriveError(f"recipe {name!r}: algo must be one of {sorted(ALGOS)}, not {algo!r}")
    check_keys(recipe, RECIPE_KEYS, f"recipe {name!r}")
    check_removed(recipe, f"recipe {name!r}")
    params = set(inspect.signature(ALGOS[algo].__init__).parameters) - {"self", "policy", "env", "seed", "device",
                                                                        "verbose", "tensorboard_log", "action_noise"}
    check_keys(recipe.get("hyperparameters") or {}, params, f"recipe {name!r}", "hyperparameters.")
    from zodrive.training.schema import validate_hyperparameters

    validate_hyperparameters(recipe.get("hyperparameters") or {}, f"recipe {name!r}")
    steps = recipe.get("total_timesteps")
    if not isinstance(steps, int) or steps < 1:
        raise ZodriveError(f"recipe {name!r}: total_timesteps must be a positive integer")
    every = recipe.get("checkpoint_every")
    if every is not None and (isinstance(every, bool) or not isinstance(every, int) or every < 0):
        raise ZodriveError(f"recipe {name!r}: checkpoint_every must be an integer >= 0 (0: no checkpoints), "
                           f"not {every!r}")
    check_init(recipe, f"recipe {name!r}")
    return recipe


def check_init(recipe: dict[str, Any], context: str) -> dict[str, float] | None:
    """Check a DDPG / TD3 recipe's `init: MODEL` and `calibrate: {episodes, td_steps}` (start from a
    cloned actor, then fit the critics to its returns by critic-only updates; `finetune`). Returns the
    calibration settings with defaults, or None. Options that would be ignored are errors."""
    init, spec = recipe.get("init"), recipe.get("calibrate")
    if init is None:
        if spec is not None:
            raise ZodriveError(f"{context}: calibrate needs init: MODEL "
                               "(it calibrates the values of an initial network)")
        return None
    if recipe.get("double_q"):
        raise ZodriveError(f"{context}: init applies to recipes without double_q only")
    if not isinstance(init, str) or not init:
        raise ZodriveError(f"{context}: init must be a model path (a zip or model folder), not {init!r}")
    if spec is None:
        return None
    if not isinstance(spec, dict) or set(spec) - set(CALIBRATE_KEYS):
        raise ZodriveError(f"{context}: calibrate must be {{{', '.join(CALIBRATE_KEYS)}}}, not {spec!r}")
    settings = {**CALIBRATE_KEYS, **spec}
    if any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in settings.values()):
        raise ZodriveError(f"{context}: calibrate values must be numbers, not {spec!r}")
    if not (isinstance(settings["episodes"], int) and settings["episodes"] >= 1
            and isinstance(settings["td_steps"], int) and settings["td_steps"] >= 0):
        raise ZodriveError(f"{context}: calibrate needs episodes >= 1 and td_steps >= 0 (integers)")
    return settings


def _start_from_init(model: Any, recipe: dict[str, Any], preset: dict[str, Any], seed: int) -> dict | None:
    """Load `init` into the actor and target actor; with `calibrate`, let it drive and fit the critics
    to its returns (`finetune.collect`, `finetune.evaluate_critic`). Returns what was done."""
    if recipe.get("init") is None:
        return None
    from zodrive.training import finetune

    done: dict[str, Any] = {"init": finetune.init_actor_from_model(model, recipe["init"])}
    settings = check_init(recipe, "recipe")
    if settings is not None:
        start = time.perf_counter()
        env = make_env(preset)
        done["collect"] = finetune.collect(model, env, int(settings["episodes"]), DEMO_SEEDS + 1000 * seed)
        env.close()
        done["evaluate_critic"] = finetune.evaluate_critic(model, int(settings["td_steps"]), int(model.batch_size))
        log.info("critic of %s evaluated: %s", recipe["init"], done["evaluate_critic"])
        done["wall_time_s"] = round(time.perf_counter() - start, 1)
    return done


def _configure_guide(model: Any, recipe: dict[str, Any], preset: dict[str, Any]) -> None:
    """Give a GuidedTD3 / GuidedDDPG its guide from the recipe's `guide: {name: init|rules, imitation: W,
    error: squared|absolute}` (TD3+BC's term): the init model's actor kept frozen, or the continuous rules."""
    from zodrive.training.actor_critic_variants import IMITATION_ERRORS

    spec = recipe["guide"]
    if not isinstance(spec, dict) or spec.get("name") not in GUIDES or set(spec) - GUIDE_KEYS:
        raise ZodriveError(f"recipe guide of a {recipe['algo']} recipe must be {{name: {'|'.join(GUIDES)}, "
                           f"imitation: W, error: E}}, not {spec!r}")
    weight, error = spec.get("imitation", 0.4), spec.get("error", "squared")
    if isinstance(weight, bool) or not isinstance(weight, (int, float)) or weight < 0:
        raise ZodriveError(f"recipe guide: imitation must be a number >= 0, not {weight!r}")
    if error not in IMITATION_ERRORS:
        raise ZodriveError(f"recipe guide: error must be one of {', '.join(IMITATION_ERRORS)}, not {error!r}")
    if spec["name"] == "rules":
        from zodrive.drivers.rules import ContinuousRules

        guide = ContinuousRules(preset).controls
    elif recipe.get("init") is None:
        raise ZodriveError("recipe guide: name init needs init: MODEL (the actor it keeps the learner near)")
    else:
        from zodrive.training.finetune import frozen_actor

        guide = frozen_actor(model, recipe["init"])
    model.configure_guide(guide, float(weight), error)


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


def make_training_env(preset: dict[str, Any], seed: int, log_dir: Path, *, append: bool = False) -> DummyVecEnv:
    """One monitored environment; its episode returns become the training curve."""

    def build():
        return Monitor(make_env(preset), filename=str(log_dir / "monitor"), override_existing=not append)

    venv = DummyVecEnv([build])
    venv.seed(seed)
    return venv


def checkpoints(out: Path, algo: str) -> list[tuple[int, Path]]:
    """Every `checkpoints/{algo}_{N}_steps.zip` of a run folder as (N, path), oldest first."""
    found = []
    for path in (out / "checkpoints").glob(f"{algo}_*_steps.zip"):
        try:
            found.append((int(path.stem.split("_")[1]), path))
        except (IndexError, ValueError):
            continue
    return sorted(found)


SIGNATURES = "SIGNATURES.json"
"""Beside the checkpoints: each file's HMAC under this machine's zodrive key (`runinfo.signature`).
A checkpoint is unpickled on --resume only if it verifies (this machine wrote it) or the user
says --trust-model: a run folder from someone else runs no code."""


class SignedCheckpoints(CheckpointCallback):
    """SB3's checkpoints, each file signed as it is written."""

    def _on_step(self) -> bool:
        going = super()._on_step()
        if self.n_calls % self.save_freq == 0:  # the files SB3 has just written for this step
            steps = self.num_timesteps
            sign_checkpoints(Path(self.save_path), [f"{self.name_prefix}_{steps}_steps.zip",
                                                    f"{self.name_prefix}_replay_buffer_{steps}_steps.pkl"])
        return going


def sign_checkpoints(folder: Path, names: list[str]) -> None:
    """Sign the checkpoint files `names` in `folder`, just written by this process."""
    signed = _signatures(folder)
    for name in names:
        if (folder / name).is_file():
            signed[name] = signature(folder / name)
    write_json(folder / SIGNATURES, signed)


def _signatures(folder: Path) -> dict[str, str]:
    """The signatures recorded beside the checkpoints in `folder` (none if the file is missing or damaged)."""
    path = folder / SIGNATURES
    try:
        signed = json.loads(path.read_text()) if path.is_file() else {}
    except (json.JSONDecodeError, UnicodeDecodeError):
        return {}
    return signed if isinstance(signed, dict) else {}


def check_signed(files: list[Path], trust: bool) -> None:
    """Refuse to unpickle checkpoint `files` that this machine did not write, unless `trust`."""
    if trust:
        return
    signed = _signatures(files[0].parent)
    for file in files:
        if signed.get(file.name) != signature(file):
            raise ZodriveError(f"{file} was not written by zodrive on this machine: resuming unpickles it, which can "
                               "run code from the file; pass --trust-model if the run folder is yours")


def _without_budget(recipe: Any) -> Any:
    return {k: v for k, v in recipe.items() if k != "total_timesteps"} if isinstance(recipe, dict) else recipe


def check_run_folder(out: Path, *, resume: bool, force: bool, resumable: bool = True) -> None:
    """Refuse to write a run into a folder that already holds one, unless told what to do."""
    if resume or force or not out.exists() or not any(out.iterdir()):
        return
    how = "use --resume to continue it, --force to overwrite it" if resumable else "use --force to overwrite it"
    raise ZodriveError(f"{out} already holds a run; {how}, or choose another --out")


RUN_FILES = ("checkpoints", "tb", "model.zip", "train.json", "config.yaml", "run.json", "monitor.monitor.csv",
             "progress.csv", "selected.json")
"""What a training run (and `select`, which picks among its checkpoints) writes into its folder."""


def clear_run(out: Path) -> None:
    """`--force`: remove the old run's files, so that none of its later checkpoints is taken for this run's;
    what `train` did not write (a card, an evaluation of the old model) is kept, and named."""
    if not out.is_dir():
        return
    for name in RUN_FILES:
        path = out / name
        if path.is_dir():
            shutil.rmtree(path)
        elif path.exists():
            path.unlink()
    kept = sorted(p.name for p in out.iterdir())
    if kept:
        log.warning("%s: --force removed the old run; kept what train did not write (it may describe the old "
                    "model): %s", out, ", ".join(kept))


@one_torch_thread  # small MLPs: one thread is fastest and lets runs share cores
def train(
    recipe: dict[str, Any],
    out: Path,
    *,
    seed: int | None = None,
    preset_overrides: list[str] | None = None,
    progress_bar: bool = True,
    tensorboard: bool = False,
    resume: bool = False,
    force: bool = False,
    trust: bool = False,
) -> Path:
    """Train per `recipe` into run folder `out`; returns the saved model path.

    Checkpoints (model and replay buffer) are written every `checkpoint_every` steps; with
    `resume`, training continues from the newest one with the run's own recipe and seed (the
    environment restarts from a fresh episode, so a resumed run is not bit-identical to an
    uninterrupted one)."""
    check_removed(recipe, f"recipe {recipe.get('algo')}")
    check_run_folder(out, resume=resume, force=force)
    if resume and not (out / "config.yaml").is_file():
        raise ZodriveError(f"nothing to resume in {out}: it holds no run (drop --resume to start one)")
    previous = read_yaml(out / "config.yaml") if resume else None
    if previous is not None and _without_budget(previous.get("recipe")) != _without_budget(recipe):
        raise ZodriveError(f"{out} was trained with another recipe; --resume continues a run as it was started "
                           "(only --steps may change, to train it longer)")
    seed = int(recipe.get("seed", 0) if seed is None else seed)
    if previous is not None:
        seed = int(read_json(out / "run.json", needs=("seed",))["seed"])
    algo = recipe["algo"]
    preset = load_preset(recipe.get("preset", KIND_OF_ALGO[algo]), preset_overrides)
    if action_kind(preset) != KIND_OF_ALGO[algo]:
        raise ZodriveError(f"{algo} needs a {KIND_OF_ALGO[algo]} preset, not {preset['name']!r}")
    if force and not resume:
        clear_run(out)
    fresh = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    try:
        return _train(recipe, out, seed, preset, resume=resume, previous=previous, progress_bar=progress_bar,
                      tensorboard=tensorboard, trust=trust)
    except (ZodriveError, TypeError, ValueError, AssertionError) as exc:  # a recipe option (guide, init) or SB3
        if fresh:
            shutil.rmtree(out, ignore_errors=True)  # leave no half-made run folder behind
        if isinstance(exc, ZodriveError):
            raise
        raise ZodriveError(f"recipe {recipe.get('algo')}: invalid setting ({cause(exc)})") from exc


def check_n_step_buffer(model: Any, recipe: dict[str, Any]) -> None:
    """A resumed off-policy run keeps the recipe's n-step returns, or a one-line error. On a load SB3 (2.6+)
    warns that `n_steps` "is ignored because a custom replay_buffer_class was passed": the class is the
    `NStepReplayBuffer` it chose itself when the run started, and the saved buffer arguments still carry
    `n_steps`, so the returns stay n-step. This checks that instead of trusting the warning."""
    if not hasattr(model, "replay_buffer_kwargs"):  # on-policy (PPO): n_steps is the rollout's length
        return
    want = int((recipe.get("hyperparameters") or {}).get("n_steps", 1))
    got = int(getattr(model.replay_buffer, "n_steps", 1))
    if got != want:
        raise ZodriveError(f"the checkpoint resumes with {got}-step returns, the recipe says n_steps: {want}")


def _train(recipe: dict[str, Any], out: Path, seed: int, preset: dict[str, Any], *, resume: bool,
           previous: dict[str, Any] | None, progress_bar: bool, tensorboard: bool, trust: bool = False) -> Path:
    algo = recipe["algo"]
    found = checkpoints(out, algo) if resume else []
    checkpoint = found[-1] if found else None  # the newest: (steps, path)
    if previous is None:
        write_run_info(out, {"recipe": recipe, "preset": preset}, seed)
    else:  # the run folder keeps the command that started it and lists those that continued it
        run = read_json(out / "run.json", needs=("command",))
        run["continued_by"] = [*run.get("continued_by", []), command_line()]
        write_json(out / "run.json", run)
        write_atomic(out / "config.yaml", yaml.safe_dump({**previous, "recipe": recipe}, sort_keys=False))

    env = make_training_env(preset, seed if checkpoint is None else seed + checkpoint[0], out,
                            append=checkpoint is not None)
    if checkpoint is None:
        kwargs = dict(recipe.get("hyperparameters") or {})
        if algo in ACTOR_CRITIC:
            assert env.action_space.shape is not None  # continuous actions: a Box
            kwargs["action_noise"] = action_noise(recipe.get("action_noise"), env.action_space.shape[0])
        model = algorithm_class(recipe)(
            "MlpPolicy",
            env,
            seed=seed,
            device="cpu",
            verbose=0,
            tensorboard_log=str(out / "tb") if tensorboard else None,
            **kwargs,
        )
        done = 0
    else:
        done, path = checkpoint
        buffer = path.with_name(f"{algo}_replay_buffer_{done}_steps.pkl")
        check_signed([path, *([buffer] if buffer.is_file() else [])], trust)
        with warnings.catch_warnings():  # SB3 says n_steps is ignored, wrongly on a load: `check_n_step_buffer`
            warnings.filterwarnings("ignore",
                                    message=r"`n_steps=\d+` is ignored because a custom `replay_buffer_class`")
            model = algorithm_class(recipe).load(path, env=env, device="cpu")  # signed by this machine, or trusted
        check_n_step_buffer(model, recipe)
        if buffer.is_file():
            model.load_replay_buffer(buffer)
        log.warning("resuming %s from step %d (%s)", out, done, path.name)
    if recipe.get("guide"):
        _configure_guide(model, recipe, preset)
    model.set_logger(configure(str(out), ["csv"] + (["tensorboard"] if tensorboard else [])))
    initial = _start_from_init(model, recipe, preset, seed) if checkpoint is None else None
    every = int(recipe.get("checkpoint_every", 0) or 0)
    if initial and every:  # the calibrated start is a checkpoint too: the curve's first point, a candidate
        (out / "checkpoints").mkdir(exist_ok=True)
        model.save(out / "checkpoints" / f"{algo}_0_steps.zip")
        sign_checkpoints(out / "checkpoints", [f"{algo}_0_steps.zip"])
    callback = SignedCheckpoints(every, str(out / "checkpoints"), name_prefix=algo,
                                  save_replay_buffer=True) if every else None
    start = time.perf_counter()
    total = int(recipe["total_timesteps"])
    if done < total:
        model.learn(
            total_timesteps=total - done,
            callback=callback,
            progress_bar=progress_bar,
            log_interval=1 if algo in ACTOR_CRITIC else 4,
            reset_num_timesteps=checkpoint is None,
        )
    wall = time.perf_counter() - start  # of this invocation: steps done-total
    path = out / "model.zip"
    model.save(path)
    write_json(
        out / "train.json",
        {"algo": algo, "total_timesteps": total, "seed": seed, "resumed_from": done or None,
         "wall_time_s": round(wall, 1), "steps_per_s": round((total - done) / max(wall, 1e-9), 1),
         **({"initial": initial} if initial else {})},
    )
    env.close()
    log.info("trained %s for %d steps in %.0f s", algo, recipe["total_timesteps"], wall)
    return path
