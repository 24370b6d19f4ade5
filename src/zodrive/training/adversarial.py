"""Adversarial training (the paper's Algorithm 2, after Pattanaik et al. 2018).

Continue training a trained DQN/DDPG where every observation the agent acts on and stores
in its replay buffer is the attacked one. The attack queries the *current* policy: the
victim wraps the very networks that SB3 updates, so attacker and learner stay in sync.
The same `AttackWrapper` as evaluation does the work; reward per episode is logged.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any, Callable, cast

from stable_baselines3 import DQN
from stable_baselines3.common.logger import configure
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.utils import LinearSchedule
from stable_baselines3.common.vec_env import DummyVecEnv

from zodrive.compute import one_torch_thread
from zodrive.policies.loading import load_model, model_algo, model_file
from zodrive.training.recipes import action_noise, check_run_folder
from zodrive.policies.victims import sb3_victim
from zodrive.attacks.spec import AttackSpec
from zodrive.errors import ZodriveError
from zodrive.runinfo import write_json, write_run_info
from zodrive.system import make_attacked_env
from zodrive.system import build_attacker

log = logging.getLogger(__name__)


@one_torch_thread  # small MLPs: one thread is fastest and lets runs share cores
def adversarial_train(
    model_path: str | Path,
    preset: dict[str, Any],
    spec: AttackSpec | None,
    steps: int,
    out: Path,
    *,
    seed: int = 1,
    warmup: int = 1000,
    noise: dict[str, Any] | None = None,
    progress_bar: bool = True,
    trust: bool = False,
    force: bool = False,
    algo_class: type | None = None,
    setup: Callable[[Any], dict[str, Any]] | None = None,
) -> Path:
    """Train `model_path` for `steps` more steps on attacked observations; save to `out`.

    `spec=None` is the control run: the very same continued training (same seed, buffer,
    exploration, updates) on clean observations, so that what the attack changes can be told
    apart from what restarting the training changes. `algo_class` loads the model as a
    subclass of its algorithm (e.g. SA-DQN) and `setup(model)` sets it up before training;
    what it returns is recorded in run.json and train.json."""
    if steps < 1:
        raise ZodriveError(f"steps must be >= 1, not {steps}")
    check_run_folder(out, resume=False, force=force, resumable=False)
    source = model_file(model_path)
    algo = model_algo(source)
    model = load_model(source, preset, trust=trust, cls=algo_class)  # an SB3 object to train further
    assert isinstance(model, OffPolicyAlgorithm)  # DQN, DDPG or TD3 (`ALGOS`)
    victim = sb3_victim(model)  # live view of the networks being trained
    if spec is not None:  # the whole attack is checked before the run folder exists

        if spec.adversary is not None:  # fitted against one model file, while this run changes the model
            raise ZodriveError(f"adv-train trains against attacks that adapt to the changing model; "
                               f"{spec.attack}:{spec.adversary} was fitted against one fixed model file")
        build_attacker(spec, victim, preset)
    out.mkdir(parents=True, exist_ok=True)
    method = setup(model) if setup is not None else None
    write_run_info(out, {"source_model": str(source), "preset": preset, "attack": spec and spec.to_dict(),
                         "steps": steps, "warmup": warmup, "action_noise": noise, "method": method}, seed)

    def build():
        env = make_attacked_env(preset, victim, spec)  # reseeded by the seeded reset below
        keys = ("crashed",) if spec is None else ("crashed", "attack_success_rate", "attack_queries")
        return Monitor(env, filename=str(out / "monitor"), info_keywords=keys)

    venv = DummyVecEnv([build])
    venv.seed(seed)
    model.set_env(venv)
    model.set_random_seed(seed)
    # Algorithm 2 acts with the (attacked) policy from the first step. SB3 would take *random*
    # actions until `learning_starts`, and updating from the first step on a nearly empty
    # buffer degrades the policy by itself (the control run without attack showed it). So the
    # buffer is first filled with `warmup` transitions of the policy acting on attacked
    # observations, without updates, and then `steps` steps of training follow.
    model.learning_starts = 0
    if algo == "dqn":  # keep exploring at the final rate instead of restarting the schedule at 1.0
        assert isinstance(model, DQN)
        eps = model.exploration_final_eps
        model.exploration_schedule = LinearSchedule(eps, eps, 1.0)
    else:
        assert venv.action_space.shape is not None  # DDPG/TD3 act in a Box
        model.action_noise = action_noise(noise or {"type": "normal", "sigma": 0.1}, venv.action_space.shape[0])
    model.set_logger(configure(str(out), ["csv"]))
    start = time.perf_counter()
    log_interval = 1 if algo == "ddpg" else 4
    if warmup:
        gradient_steps, model.gradient_steps = model.gradient_steps, 0
        model.learn(total_timesteps=warmup, reset_num_timesteps=True, progress_bar=progress_bar,
                    log_interval=log_interval)
        model.gradient_steps = gradient_steps
    model.learn(total_timesteps=steps, reset_num_timesteps=not warmup, progress_bar=progress_bar,
                log_interval=log_interval)
    wall = time.perf_counter() - start
    path = out / "model.zip"
    model.save(path)
    oracle = getattr(cast(Monitor, venv.envs[0]).env, "oracle", None)  # `build`'s Monitor
    write_json(out / "train.json", {
        "algo": algo, "kind": "adversarial" if spec is not None else (method or {}).get("name", "control (no attack)"),
        "method": method, "source_model": str(source),
        "total_timesteps": steps, "warmup_steps": warmup,
        "seed": seed, "wall_time_s": round(wall, 1), "steps_per_s": round(steps / wall, 1),
        "attack_queries": int(oracle.total_queries) if oracle is not None else 0,
    })
    venv.close()
    return path
