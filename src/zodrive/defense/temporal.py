"""Temporal smoothing (`--defense temporal[@K]`): each vehicle is seen as the median of its last K sightings.

The defense the RoAd-RL benchmark (2026) finds to help most consistently against observation attacks on
highway-env: a filter over time, in the spirit of median filtering of sensor tracks. A plain per-row
median would mix vehicles, since highway-env lists them nearest first and the order changes; and at one
decision a second, a vehicle 10 m/s faster moves 10 m between sightings. So each of the last K - 1
received observations is carried to now under constant velocity (`tracks.advance`), its rows are paired
with the new ones (`tracks.match`, one to one, nearest first), and each feature of a row becomes the
median of its current value and those of its paired sightings (a row without a pair keeps its value;
presence is taken as received).

What it assumes: Kinematics rows (presence, x, y, vx, vy first; further features such as heading are
smoothed by value, not carried) and the scenario's decision rate. What it cannot stop: a perturbation
held over K steps (the median of K shifted sightings is shifted: the attacks of the bench carry their
perturbation from step to step, `warm_start`); a vehicle that appears (nothing to compare it with).
What it costs clean: the lag of a vehicle whose speed or lane changes within the window.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

from zodrive.defense import tracks
from zodrive.errors import ZodriveError

VERSION = 1
"""The behaviour of `temporal@K`, recorded in every result key that names it."""
DEFAULT_WINDOW = 3
"""`temporal` = `temporal@3`: the current sighting and two earlier ones (a median needs three)."""
GATE = 0.2
"""Largest |dx| + |dy| (normalized) to pair a carried row with a new one: wider than two ε 0.05 shifts of
both coordinates, narrower than a lane change on the roads whose y range is the widest."""
FIRST = ("presence", "x", "y", "vx", "vy")


def parse_temporal(name: str) -> int | None:
    """K of `temporal[@K]` (None if `name` is not this defense); one line for a bad K."""
    base, at, k = str(name).partition("@")
    if base != "temporal":
        return None
    if not at:
        return DEFAULT_WINDOW
    if not k.isdigit() or not 2 <= int(k) <= 10:
        raise ZodriveError(f"{name}: temporal@K takes a window K of 2 to 10 observations, e.g. temporal@3")
    return int(k)


class TemporalMedian:
    """A stateful filter (`EpisodeFilter`): the last K - 1 received observations and their ages."""

    def __init__(self, preset: dict[str, Any], window: int = DEFAULT_WINDOW) -> None:
        from zodrive.envs import scenario

        where = scenario(preset)
        if tuple(where.features[:5]) != FIRST or len(where.obs_shape) != 2 or not where.normalized:
            raise ZodriveError("temporal smoothing follows vehicles through highway-env's normalized Kinematics "
                               f"observation (features {', '.join(FIRST)} first); {where.name} observes "
                               f"{', '.join(where.features) or 'unnamed features'}")
        frequency = float(where.policy_frequency or 0)
        if frequency <= 0:
            raise ZodriveError(f"temporal smoothing carries sightings between decisions: {where.name}'s decision rate "
                               "is not known")
        ranges = where.feature_ranges
        self.kx = float(ranges["vx"][1]) / float(ranges["x"][1]) / frequency  # normalized x change per step per vx
        self.ky = float(ranges["vy"][1]) / float(ranges["y"][1]) / frequency
        self.window = int(window)
        self.relative = where.relative
        self._past: deque[np.ndarray] = deque(maxlen=self.window - 1)
        self._carried: list[np.ndarray] = []

    @property
    def state(self) -> list[np.ndarray] | None:
        return list(self._past) if self._past else None

    @state.setter
    def state(self, value: list[np.ndarray] | None) -> None:
        self._past.clear()
        self._past.extend([] if value is None else value)
        self._carried = self._carry()

    def _carry(self) -> list[np.ndarray]:
        """Every kept sighting carried to the coming step (the newest is one step old)."""
        n = len(self._past)
        return [tracks.advance(obs, n - i, self.kx, self.ky, self.relative) for i, obs in enumerate(self._past)]

    def reset(self, obs: np.ndarray) -> np.ndarray:
        self.state = None
        return self.update(obs)

    def update(self, obs: np.ndarray) -> np.ndarray:
        out = self.peek(np.asarray(obs)[None])[0]
        self._past.append(np.array(obs, dtype=np.float32, copy=True))
        self._carried = self._carry()
        return out

    def peek(self, batch: np.ndarray) -> np.ndarray:
        """Smooth observations (B, V, F) with the kept sightings, without changing them."""
        batch = np.asarray(batch, dtype=np.float32)
        if not self._carried:
            return batch.copy()
        b, v, f = batch.shape
        stack = np.full((len(self._carried) + 1, b, v, f), np.nan, dtype=np.float32)
        stack[0] = batch
        for s, ref in enumerate(self._carried, start=1):
            pairs = tracks.match(batch, ref, GATE)
            stack[s, :, 0] = ref[0]  # the ego row pairs with the ego row
            bi, oi = np.nonzero(pairs >= 0)
            stack[s, bi, 1 + oi] = ref[1 + pairs[bi, oi]]
        out = np.nanmedian(stack, axis=0).astype(np.float32)
        out[:, :, 0] = batch[:, :, 0]  # presence as received
        return out
