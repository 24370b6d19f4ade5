"""Reinforcement learning that starts from a cloned driver (issue 22, item 2), continuous side.

A cloned DDPG / TD3 actor (`models/ddpg-imitation`) keeps its outputs as they are: it goes into the
actor and target actor (`init_actor_from_model`), drives into the buffer with the recipe's exploration
noise (`collect`), and the fresh critics are fitted to its returns by critic-only TD updates
(`evaluate_critic`) before the first actor update (then `GuidedTD3`, TD3+BC). The DQN side (LSTD-Q
calibration of a cloned Q-network, DQfD's margin loss) lost and was removed (issue 45;
results/finetune/README.md).
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import numpy as np
import torch as th
from torch.nn import functional as F

from zodrive.errors import ZodriveError
from zodrive.runinfo import sha256

ACTOR_PREFIX = "actor.mu."  # SB3 DDPG / TD3: the actor's MLP in policy.pth
ACTOR_KIND = "DDPG or TD3 (no actor weights)"
EVALUATION_TAU = 0.05  # Polyak rate of the target critics during `evaluate_critic`


def init_actor_from_model(model: Any, path: str | Path) -> dict[str, Any]:
    """Copy the actor of the DDPG / TD3 zip at `path` (file or model folder) into `model`'s actor
    and target actor; the critics stay freshly initialized (`evaluate_critic` fits them). Read
    without unpickling; a missing, non-DDPG/TD3 or differently shaped model is a one-line error."""
    file = _load_network(model.actor, path, ACTOR_PREFIX, "actor.", ACTOR_KIND)
    model.actor_target.load_state_dict(model.actor.state_dict())
    return {"model": str(file), "sha256": sha256(file), "part": "actor"}


def frozen_actor(model: Any, path: str | Path) -> Any:
    """The actor of the DDPG / TD3 zip at `path` as a frozen function (B, ...) observations -> (B, dims)
    actions: a copy of `model`'s actor with those weights (read without unpickling). A guide that keeps
    the learner near the policy it started from (a behaviour-regularized objective), the same on resume."""
    actor = copy.deepcopy(model.actor).requires_grad_(False)
    _load_network(actor, path, ACTOR_PREFIX, "actor.", ACTOR_KIND)

    def act(observations: np.ndarray) -> np.ndarray:
        with th.no_grad():
            return actor(th.as_tensor(observations, dtype=th.float32)).numpy()

    return act


def _load_network(network: Any, path: str | Path, prefix: str, strip: str, kind: str) -> Path:
    """Load into `network` the weights under `prefix` in the zip at `path` (file or model folder),
    keys without `strip`, read without unpickling; returns the zip's path. A missing file, a zip
    without them or layers of other names or shapes are one-line ZodriveErrors."""
    from zodrive.policies.loading import model_file
    from zodrive.policies.safe_load import read_plain

    file = model_file(path)
    _, weights = read_plain(file)
    theirs = {k[len(strip):]: v for k, v in weights.items() if k.startswith(prefix)}
    if not theirs:
        raise ZodriveError(f"init model {file} is not a {kind}; init needs one")
    ours = network.state_dict()
    if set(theirs) != set(ours):
        raise ZodriveError(f"init model {file} has layers {sorted(theirs)}; the recipe's network has {sorted(ours)}")
    for key, value in ours.items():
        if tuple(theirs[key].shape) != tuple(value.shape):
            raise ZodriveError(f"init model {file}: {key} has shape {tuple(theirs[key].shape)}, the recipe's "
                               f"network {tuple(value.shape)} (policy_kwargs.net_arch and the preset must match)")
    network.load_state_dict({k: v.to(dtype=ours[k].dtype) for k, v in theirs.items()})
    return file


def drive_into_buffer(buffer: Any, env: Any, episodes: int, seed: int, choose: Any) -> list[float]:
    """Drive `episodes` episodes of `env` (seeds `seed`, `seed` + 1, ...) acting with `choose(obs)`
    and add every transition to the replay `buffer`; returns the episodes' returns."""
    returns = []
    for episode in range(episodes):
        obs, _ = env.reset(seed=seed + episode)
        total, done = 0.0, False
        while not done:
            action = choose(obs)
            next_obs, reward, terminated, truncated, _ = env.step(action)
            done = terminated or truncated
            buffer.add(obs[None], next_obs[None], np.reshape(action, (1, -1)), np.array([reward]), np.array([done]),
                       [{"TimeLimit.truncated": truncated and not terminated}])
            obs, total = next_obs, total + float(reward)
        returns.append(total)
    return returns


def collect(model: Any, env: Any, episodes: int, seed: int) -> dict[str, Any]:
    """Drive `episodes` episodes of `env` (seeds `seed`, `seed` + 1, ...) with the DDPG / TD3 model's
    deterministic action plus its recipe's exploration noise (`model.action_noise`), clipped to [-1, 1]
    (the noise is drawn from numpy's global generator, which SB3 seeds with the run's seed), and add
    every transition to its replay buffer. Returns counts and the mean return."""

    def choose(obs: np.ndarray) -> Any:  # the actor's [-1, 1] space is the preset's (checked by the recipe)
        with th.no_grad():
            action = model.actor(th.as_tensor(obs[None], dtype=th.float32))[0].numpy()
        return action if model.action_noise is None else np.clip(action + model.action_noise(), -1.0, 1.0)

    returns = drive_into_buffer(model.replay_buffer, env, episodes, seed, choose)
    return {"episodes": episodes, "seeds_from": seed, "transitions": int(model.replay_buffer.size()),
            "mean_return": round(float(np.mean(returns)), 3)}


def evaluate_critic(model: Any, steps: int, batch_size: int) -> dict[str, Any]:
    """`steps` critic-only TD3 / DDPG updates on the replay buffer (`GuidedTD3.train_actor` off, so
    the targets use the frozen actor's next actions): policy evaluation of the initial driver, so
    that the first actor updates follow a critic of *its* returns, not a random one. Returns the
    one-step TD loss on a fixed sample of the buffer before and after, and the critic's mean value.
    The target critics follow at `EVALUATION_TAU` (at TD3's 0.005 they would lag the values over
    some 400 updates each, and values of a 100-step horizon need many such lags to build up)."""
    data = model.replay_buffer.sample(min(4096, int(model.replay_buffer.size())))

    def td_loss() -> float:
        with th.no_grad():
            discounts = data.discounts if data.discounts is not None else model.gamma
            next_q = th.cat(model.critic_target(data.next_observations, model.actor_target(data.next_observations)),
                            dim=1).min(dim=1, keepdim=True)[0]
            target = data.rewards + (1 - data.dones) * discounts * next_q
            return float(F.mse_loss(model.critic.q1_forward(data.observations, data.actions), target))

    before = td_loss()
    model.train_actor, tau = False, model.tau
    model.tau = max(tau, EVALUATION_TAU)
    try:
        model.train(steps, batch_size)
    finally:
        model.train_actor, model.tau = True, tau
    with th.no_grad():
        value = model.critic.q1_forward(data.observations, model.actor(data.observations))
    return {"td_steps": steps, "td_loss_before": round(before, 4), "td_loss_after": round(td_loss(), 4),
            "mean_q": round(float(value.mean()), 4), "mean_reward": round(float(data.rewards.mean()), 4)}
