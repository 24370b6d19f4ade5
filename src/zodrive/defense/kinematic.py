"""A kinematic-consistency observation filter: physics between the sensor and the policy.

Between two decisions (1/15 s) no vehicle can teleport: a tracked vehicle's relative
position moves by its relative velocity times dt, and its relative velocity changes by at
most what accelerations allow. The filter keeps an estimate of every observed vehicle,
predicts it one step ahead (constant relative velocity), matches the new observation's rows
to the predictions (greedy, nearest first, within a gate) and clamps each matched row to
prediction +- a tolerance per feature. The filtered observation is the new estimate.

What it assumes: the preset's Kinematics observation (features presence, x, y, vx, vy,
relative to the ego, normalized by `features_range`, sorted by distance), a fixed policy
frequency, no sensor noise beyond the tolerances (calibrated on clean episodes of tuning
seeds: the largest one-step change seen, times a margin). What it cannot stop: a
perturbation that drifts no faster than the tolerances allow (velocity offsets build up in a
few steps, position offsets only through them, slowly); a row that no prediction matches
(a vehicle entering the observed set) is taken as it is; the presence flags and the first
observation of an episode are trusted.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from zodrive.defense import tracks
from zodrive.errors import ZodriveError

FEATURES = ("presence", "x", "y", "vx", "vy")
CALIBRATED = (15.0, 100.0, 20.0)
"""Where `Tolerances` were measured: decisions per second, and the x and vx ranges of the normalization."""


@dataclass(frozen=True)
class Tolerances:
    """Largest accepted departure from the one-step prediction [normalized units].

    Measured on clean episodes (tuning seeds 50000+, the shipped DQN with random actions
    mixed in): one-step prediction errors reached x 0.0011, y 0.0041, vx 0.035, vy 0.16 for
    other vehicles, and the ego's own vx and vy changed by up to 0.035 and 0.16. The
    defaults are about 1.5x those.
    """

    x: float = 0.002
    y: float = 0.006
    vx: float = 0.05
    vy: float = 0.25
    gate: float = 0.3  # max (|dx| + |dy|) to match a row to a track: wider than eps 0.2


class KinematicFilter:
    """Stateful filter: `reset(obs)` at an episode start, `update(obs)` each step; `peek`
    filters candidate observations against the current state without advancing it (what a
    black-box attacker of the defended system may query)."""

    def __init__(self, preset: dict[str, Any], tol: Tolerances | None = None) -> None:
        obs = (preset.get("highway") or {}).get("observation")
        if not isinstance(obs, dict):
            raise ZodriveError(f"the kinematic filter reads highway-env's Kinematics observation; {preset.get('name')} "
                               "is not a highway-env preset")
        features = tuple(obs.get("features", FEATURES))
        if features != FEATURES or obs.get("absolute", False) or not obs.get("normalize", True):
            raise ZodriveError("the kinematic filter needs the relative, normalized Kinematics observation "
                               f"with features {', '.join(FEATURES)}")
        from zodrive.envs import scenario

        where = scenario(preset)  # the ranges and the frequency the environment runs with, not a guess of them
        pos, vel = float(where.feature_ranges["x"][1]), float(where.feature_ranges["vx"][1])
        frequency = float(where.policy_frequency or 0)
        if (frequency, pos, vel) != CALIBRATED:
            raise ZodriveError(f"the kinematic filter's tolerances were calibrated at {CALIBRATED[0]:g} decisions/s "
                               f"with x in ±{CALIBRATED[1]:g} m and vx in ±{CALIBRATED[2]:g} m/s (the paper's preset); "
                               f"{preset.get('name')} runs {frequency:g}/s with ±{pos:g} m and ±{vel:g} m/s: its "
                               "one-step tolerances are not known there, and a wrong one changes clean decisions")
        dt = 1.0 / frequency
        self.k = vel / pos * dt  # normalized position change per step per unit of normalized velocity
        self.tol = tol or Tolerances()
        self._width = np.array([0.0, self.tol.x, self.tol.y, self.tol.vx, self.tol.vy], dtype=np.float32)
        self._state: np.ndarray | None = None
        self._pred: np.ndarray | None = None  # the state one step ahead; every peek of a step uses it

    @property
    def state(self) -> np.ndarray | None:
        return self._state

    @state.setter
    def state(self, value: np.ndarray | None) -> None:
        self._state = value
        self._pred = None if value is None else self._predict(value)

    def reset(self, obs: np.ndarray) -> np.ndarray:
        self.state = np.array(obs, dtype=np.float32, copy=True)
        return self.state.copy()

    def update(self, obs: np.ndarray) -> np.ndarray:
        if self.state is None:
            return self.reset(obs)
        self.state = self.peek(obs[None])[0]
        return self.state.copy()

    def _predict(self, state: np.ndarray) -> np.ndarray:
        """Every tracked row one step ahead under constant (relative) velocity."""
        return tracks.advance(state, 1.0, self.k, self.k, relative=True)

    def peek(self, batch: np.ndarray) -> np.ndarray:
        """Filter observations (B, V, 5) against the current state, without changing it."""
        batch = np.asarray(batch, dtype=np.float32)
        if self.state is None:
            return batch.copy()
        pred: np.ndarray = self._pred  # type: ignore[assignment]  # set with the state: not None here
        match = tracks.match(batch, pred, self.tol.gate)
        out = batch.copy()
        # the ego row always matches the ego track
        out[:, 0] = np.clip(batch[:, 0], pred[0] - self._width, pred[0] + self._width)
        bi, oi = np.nonzero(match >= 0)
        target = pred[1 + match[bi, oi]]
        out[bi, 1 + oi] = np.clip(batch[bi, 1 + oi], target - self._width, target + self._width)
        out[:, :, 0] = batch[:, :, 0]  # presence is trusted
        return out
