"""Black-box victims: a model becomes a query function (observation batch -> outputs).

Attacks only ever see a `Victim`: a callable over numpy arrays plus how outputs map to the
action taken. SB3 models are wrapped here; any plain callable works the same way.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Literal

import numpy as np
import torch
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.torch_layers import FlattenExtractor

QueryFn = Callable[[np.ndarray], np.ndarray]
"""Observation batch (B, *obs_shape) -> outputs (B, k): Q-values or actions."""


@dataclass(frozen=True)
class Victim:
    """A query function and what its outputs are.

    `kind="discrete"`: outputs are per-action scores (e.g. Q-values); the action taken is
    their argmax. `kind="continuous"`: outputs are the action itself.
    """

    query: QueryFn
    kind: Literal["discrete", "continuous"]
    obs_shape: tuple[int, ...]
    differentiable: Callable[[torch.Tensor], torch.Tensor] | None = None
    """White-box access (torch forward with gradients); only FGSM/PGD baselines use it."""
    reads: Literal["observation", "nothing", "simulator"] = "observation"
    """What the decisions depend on: built-in baselines read nothing or the simulator."""

    def actions(self, outputs: np.ndarray) -> np.ndarray:
        """The action(s) the victim takes given its outputs."""
        return outputs.argmax(axis=-1) if self.kind == "discrete" else outputs


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
    name = type(model).__name__
    if name == "DQN":
        net, kind = policy.q_net, "discrete"
        head = net.q_net  # the MLP after SB3's flatten feature extractor
    elif name in ("DDPG", "TD3"):
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
