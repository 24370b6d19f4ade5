"""`baseline:rules`: a hand-written lane-changing driver that reads only the observation.

The same 5x5 Kinematics observation the learned agents get (the ego row absolute, up to four
vehicles ahead relative to it, normalized), turned into a meta-action by fixed rules, with
nothing remembered between steps. It answers two questions: how far does *this observation*
carry a driver that is not learned (the learned DQN and `baseline:idm-mobil`, which reads the
simulator, bracket it), and is a policy that is not a neural network any harder to attack
(it has no scores: an attacker sees only its decision, one-hot).

The rules, per observation (lanes 4 m wide, cars 5 m long):
1. The gap to the nearest vehicle ahead in each lane (own, left, right) and its closing speed;
   the safe gap is IDM's s* = s0 + v T + v dv / (2 sqrt(a b)) at an assumed own speed of
   25 m/s (above 20 m/s the observation does not show it: vx is clipped).
2. Too close in the own lane: change to a neighbouring lane whose gap is safe by a margin and
   where nothing is observed beside the ego (left first, to overtake), else SLOWER.
3. Free road: move right if the right lane is free far ahead (the reward pays for it), else
   FASTER if the own lane is free by a margin, else IDLE.
Lane changes start only near a lane centre and with no lateral motion, so that one change is
not asked for twice. Vehicles behind are not in the observation, so a lane change is blind to
them, as it is for the learned agents.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from zodrive.attacks.victim import Victim
from zodrive.errors import ZodriveError

LANE_LEFT, IDLE, LANE_RIGHT, FASTER, SLOWER = range(5)
LANE_WIDTH = 4.0       # [m] highway-env's StraightLane default
CAR_LENGTH = 5.0       # [m]
ASSUMED_SPEED = 25.0   # [m/s] own speed for the safe gap (the observation clips vx at its range)
S0, HEADWAY = 10.0, 1.0          # [m], [s] highway-env's IDM distance and time gap
A_MAX, B_COMF = 3.0, 5.0         # [m/s^2] IDM's comfort acceleration and deceleration
MARGIN = 15.0          # [m] extra gap asked of a lane before moving into it or speeding up
BESIDE = 8.0           # [m] |dx| within which a vehicle beside the ego blocks a lane change


class ObservationRules:
    """Vectorized rules: `actions(obs)` maps observations (B, V, 5) to meta-actions (B,)."""

    def __init__(self, preset: dict[str, Any]) -> None:
        obs = preset["highway"]["observation"]
        if tuple(obs.get("features", ())) != ("presence", "x", "y", "vx", "vy") or obs.get("absolute", False) \
                or not obs.get("normalize", True):
            raise ZodriveError("baseline:rules reads the relative, normalized Kinematics observation "
                               "(features presence, x, y, vx, vy)")
        if preset["highway"]["action"]["type"] != "DiscreteMetaAction":
            raise ZodriveError("baseline:rules issues meta-actions: it drives discrete presets")
        ranges = obs.get("features_range", {})
        self.scale = np.array([1.0, ranges.get("x", [-100, 100])[1], ranges.get("y", [-100, 100])[1],
                               ranges.get("vx", [-20, 20])[1], ranges.get("vy", [-20, 20])[1]], dtype=np.float64)
        self.lanes = int(preset["highway"].get("lanes_count", 4))

    def actions(self, batch: np.ndarray) -> np.ndarray:
        x = np.asarray(batch, dtype=np.float64) * self.scale  # physical units
        ego, others = x[:, 0], x[:, 1:]
        present = others[:, :, 0] > 0.5
        dx, dy, dvx = others[:, :, 1], others[:, :, 2], others[:, :, 3]
        lane = np.clip(np.rint(ego[:, 2] / LANE_WIDTH), 0, self.lanes - 1)
        centred = (np.abs(ego[:, 2] - lane * LANE_WIDTH) < 0.5) & (np.abs(ego[:, 4]) < 0.3)

        def room(offset: int) -> tuple[np.ndarray, np.ndarray]:
            """Gap ahead minus the safe gap, and whether a vehicle is beside, in lane `offset`."""
            inside = present & (np.abs(dy - offset * LANE_WIDTH) < LANE_WIDTH / 2)
            ahead = inside & (dx > 0)
            gap = np.where(ahead, dx - CAR_LENGTH, np.inf).min(axis=1)
            lead = np.where(ahead, dx, np.inf).argmin(axis=1)
            closing = np.maximum(-dvx[np.arange(len(dx)), lead], 0.0)
            safe = S0 + ASSUMED_SPEED * HEADWAY + ASSUMED_SPEED * closing / (2 * np.sqrt(A_MAX * B_COMF))
            beside = (inside & (np.abs(dx) < BESIDE)).any(axis=1)
            exists = (lane + offset >= 0) & (lane + offset <= self.lanes - 1)
            return np.where(exists, gap - safe, -np.inf), beside | ~exists

        own, _ = room(0)
        left, left_blocked = room(-1)
        right, right_blocked = room(+1)
        act = np.full(len(x), IDLE)
        act[own > MARGIN] = FASTER
        keep_right = centred & ~right_blocked & (right > MARGIN)
        act[keep_right] = LANE_RIGHT
        close = own < 0
        act[close] = SLOWER
        go_left = close & centred & ~left_blocked & (left > MARGIN)
        go_right = close & centred & ~right_blocked & (right > MARGIN) & ~go_left
        act[go_left], act[go_right] = LANE_LEFT, LANE_RIGHT
        return act


def rules_victim(preset: dict[str, Any], obs_shape: tuple[int, ...], n_actions: int) -> Victim:
    """`baseline:rules` as a victim: decisions only (one-hot), no scores and no gradients."""
    rules = ObservationRules(preset)
    eye = np.eye(n_actions, dtype=np.float32)

    def query(obs: np.ndarray) -> np.ndarray:
        return eye[rules.actions(np.asarray(obs).reshape(len(obs), *obs_shape))]

    return Victim(query=query, kind="discrete", obs_shape=obs_shape, reads="observation")
