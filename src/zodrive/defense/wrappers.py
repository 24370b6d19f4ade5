"""The stateful defenses in the loop: the defended system as the attacker queries it, and the environment
wrapper that feeds the policy the filtered observation (any `EpisodeFilter`); for episodes run side by
side, one filter per episode row (`RowFilters`)."""

from __future__ import annotations

from typing import Any, Callable

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


class RowFilters:
    """A stateful defense for N episodes run in lockstep (`zodrive.evaluation.rollout.run_lockstep`): one
    filter per episode row, each fed that row's (attacked) observations as `FilterWrapper` feeds one
    environment's, and `peek(queries, owners)` (the oracle's `front`) shows each query through the filter
    of the row it is charged to, as `defended_victim` does for one environment. So each episode is what it
    is alone. `make()` builds one filter; the first is built here, so a defense that refuses the scenario
    says so before any episode runs."""

    def __init__(self, make: Callable[[], EpisodeFilter]) -> None:
        self.make = make
        self.spare: EpisodeFilter | None = make()  # the next new row's
        self.filters: list[EpisodeFilter] = []
        self.fresh: list[bool] = []

    def start(self, row: int) -> None:
        """Row `row` (an existing one, or the next new one) begins an episode: its filter forgets the last."""
        if row == len(self.filters):
            self.filters.append(self.spare if self.spare is not None else self.make())
            self.fresh.append(True)
            self.spare = None
        self.filters[row].state = None
        self.fresh[row] = True

    def receive(self, row: int, obs: np.ndarray) -> np.ndarray:
        """What the policy of row `row` receives for the observation `obs` it was fed."""
        if self.fresh[row]:
            self.fresh[row] = False
            return self.filters[row].reset(obs)
        return self.filters[row].update(obs)

    def peek(self, batch: np.ndarray, owners: np.ndarray) -> np.ndarray:
        """Queries (B, *obs) charged to rows `owners`, each seen through its row's filter (states unchanged)."""
        out: np.ndarray | None = None
        for row in np.unique(owners):
            where = np.flatnonzero(owners == row)
            seen = np.asarray(self.filters[int(row)].peek(batch[where]))
            if out is None:
                out = np.empty((len(batch), *seen.shape[1:]), dtype=seen.dtype)
            out[where] = seen
        return batch.copy() if out is None else out

    def keep_rows(self, rows: np.ndarray) -> None:
        """Only `rows` go on, renumbered in order (their episodes ended with none waiting)."""
        self.filters = [self.filters[int(r)] for r in rows]
        self.fresh = [self.fresh[int(r)] for r in rows]
