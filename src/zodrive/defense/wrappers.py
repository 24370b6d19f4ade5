"""The stateful defenses in the loop: the defended system as the attacker queries it, and the environment
wrapper that feeds the policy the filtered observation (any `EpisodeFilter`)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from zodrive.attacks.victim import Victim
from zodrive.defense import EpisodeFilter


def defended_victim(victim: Victim, filt: EpisodeFilter) -> Victim:
    """The defended system as the attacker sees it: filter (state frozen) then policy.

    White-box access, when the policy offers it, goes through the filter by BPDA (Athalye,
    Carlini & Wagner, "Obfuscated Gradients Give a False Sense of Security", ICML 2018): the
    forward pass is filter then network, the backward pass takes the clamp as the identity,
    so PGD sees the network's gradient at the filtered point instead of the clamp's zeros."""
    differentiable = None
    if victim.differentiable is not None:
        net = victim.differentiable

        def differentiable(x: Any) -> Any:
            filtered = x.new_tensor(filt.peek(x.detach().cpu().numpy()))
            return net(x + (filtered - x).detach())  # value: filtered; gradient: identity

    return Victim(query=lambda batch: victim.query(filt.peek(batch)), kind=victim.kind,
                  obs_shape=victim.obs_shape, differentiable=differentiable, reads=victim.reads)


class FilterWrapper(gym.ObservationWrapper):
    """Applies the filter to every observation the policy receives (after any attack)."""

    def __init__(self, env: gym.Env, filt: EpisodeFilter) -> None:
        super().__init__(env)
        self.filt = filt
        self._fresh = True

    def reset(self, **kwargs: Any):
        self._fresh = True
        self.filt.state = None  # an attack on the first observation must not see the last episode
        return super().reset(**kwargs)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        if self._fresh:
            self._fresh = False
            return self.filt.reset(observation)
        return self.filt.update(observation)
