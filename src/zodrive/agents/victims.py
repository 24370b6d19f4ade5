"""Adapters that turn models into `Victim`s (query functions) for the attack library.

Attacks only ever see a `zodrive.attacks.victim.Victim`; SB3 models and torch networks are
wrapped here, any plain callable works the same way.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import torch
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.torch_layers import FlattenExtractor

from zodrive.attacks.victim import Victim


def network_victim(net: torch.nn.Module, kind: Literal["discrete", "continuous"], obs_shape: tuple[int, ...]) -> Victim:
    """A torch network over flattened observations (Q-values or action) as a victim."""
    flat = int(np.prod(obs_shape))
    net.eval()

    def query(obs: np.ndarray) -> np.ndarray:
        batch = torch.from_numpy(np.ascontiguousarray(obs, dtype=np.float32)).reshape(-1, flat)
        with torch.inference_mode():
            return net(batch).numpy()

    def forward(obs: torch.Tensor) -> torch.Tensor:
        return net(obs.reshape(-1, flat).float())

    return Victim(query=query, kind=kind, obs_shape=tuple(obs_shape), differentiable=forward)


def sb3_victim(model: BaseAlgorithm) -> Victim:
    """Wrap an SB3 DQN (Q-values) or DDPG (deterministic action) as a black-box victim."""
    obs_shape = tuple(model.observation_space.shape)
    policy = model.policy
    policy.set_training_mode(False)
    from stable_baselines3 import DQN, TD3  # DDPG is a TD3 subclass in SB3

    name = type(model).__name__
    if isinstance(model, DQN):
        net, kind = policy.q_net, "discrete"
        head = net.q_net  # the MLP after SB3's flatten feature extractor
    elif isinstance(model, TD3):
        net, kind = policy.actor, "continuous"
        head = net.mu  # MLP ending in tanh; SB3 predicts this action (space is [-1, 1])
    else:
        raise TypeError(f"no victim adapter for {name}")
    flat = int(np.prod(obs_shape))
    if not isinstance(net.features_extractor, FlattenExtractor):
        head = None  # unusual feature extractor: go through the whole network

    def query(obs: np.ndarray) -> np.ndarray:
        batch = torch.from_numpy(np.ascontiguousarray(obs, dtype=np.float32))
        with torch.inference_mode():
            if head is not None:  # same arithmetic as net(batch), without its Python overhead
                return head(batch.reshape(-1, flat)).numpy()
            return net(batch.reshape(-1, *obs_shape)).numpy()

    def forward(obs: torch.Tensor) -> torch.Tensor:
        return net(obs.reshape(-1, *obs_shape).float())

    return Victim(query=query, kind=kind, obs_shape=obs_shape, differentiable=forward)
