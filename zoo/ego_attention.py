"""An ego-attention feature extractor for SB3 policies on highway-env's Kinematics observation.

The MLP the zoo trains elsewhere reads a flattened (vehicles x features) table, so it must learn
every vehicle slot's meaning separately. This extractor embeds each vehicle row with one shared
network, fed the row and the row minus the ego's row (so the geometry relative to the ego is in
the input, as intersection's observation is in absolute coordinates); then the ego's embedding
attends over all present vehicles (the presence feature masks empty rows), as in Leurent &
Mercat, "Social attention for autonomous decision-making in dense traffic" (2019). Written here
from that description; it is a user's own architecture, so zodrive loads its zips only with
`--trust-model` and this folder on PYTHONPATH.
"""

from __future__ import annotations

import math

import gymnasium as gym
import torch
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn


class EgoAttention(BaseFeaturesExtractor):
    """(batch, vehicles, features) -> (batch, width): the ego's view of the others, ego row first."""

    def __init__(self, observation_space: gym.spaces.Box, width: int = 64, heads: int = 2) -> None:
        super().__init__(observation_space, features_dim=width)
        features = observation_space.shape[-1]
        self.heads = heads
        self.embed = nn.Sequential(nn.Linear(2 * features, width), nn.ReLU(), nn.Linear(width, width), nn.ReLU())
        self.query = nn.Linear(width, width, bias=False)
        self.key = nn.Linear(width, width, bias=False)
        self.value = nn.Linear(width, width, bias=False)
        self.combine = nn.Linear(width, width)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        rows = torch.cat([obs, obs - obs[:, :1]], dim=-1)
        x = self.embed(rows)
        batch, _, width = x.shape
        per_head = width // self.heads

        def split(t: torch.Tensor) -> torch.Tensor:
            return t.view(batch, -1, self.heads, per_head).transpose(1, 2)

        q, k, v = split(self.query(x[:, :1])), split(self.key(x)), split(self.value(x))
        scores = q @ k.transpose(-1, -2) / math.sqrt(per_head)  # (batch, heads, 1, n)
        absent = obs[..., 0] < 0.5
        absent[:, 0] = False  # the ego always attends to itself
        scores = scores.masked_fill(absent[:, None, None, :], float("-inf"))
        seen = (torch.softmax(scores, dim=-1) @ v).transpose(1, 2).reshape(batch, width)
        return (self.combine(seen) + x[:, 0]) / 2
