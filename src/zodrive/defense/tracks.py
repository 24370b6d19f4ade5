"""Rows of a Kinematics observation across steps: which row of a new observation is which vehicle.

highway-env lists the observed vehicles nearest first, so row i at one step need not be row i at the
next. The stateful defenses carry each earlier row forward under constant velocity (`advance`) and
pair the new rows with the carried ones (`match`), the ego row always with the ego row.
"""

from __future__ import annotations

import numpy as np

X, Y, VX, VY = 1, 2, 3, 4  # feature columns after presence


def advance(state: np.ndarray, steps: float, kx: float, ky: float, relative: bool) -> np.ndarray:
    """`state` (V, F) moved `steps` decisions ahead under constant velocity; `kx` (`ky`) is the normalized
    x (y) change per step per unit of normalized vx (vy). With relative rows, the ego's own x is
    clipped (not a position to move) and only its y moves."""
    pred = state.copy()
    first = 1 if relative else 0
    pred[first:, X] += steps * kx * pred[first:, VX]
    pred[:, Y] += steps * ky * pred[:, VY]
    return np.clip(pred, -1.0, 1.0)


def match(batch: np.ndarray, ref: np.ndarray, gate: float) -> np.ndarray:
    """For observations `batch` (B, V, F) and one reference (V, F), the reference row each other row
    pairs with (B, V-1; -1: none): a greedy one-to-one assignment, nearest (|dx| + |dy|) first, of
    present rows within `gate`, for all B at once."""
    b, v = batch.shape[:2]
    present = batch[:, :, 0] > 0.5
    tracked = ref[:, 0] > 0.5
    dist = np.abs(batch[:, 1:, None, X:Y + 1] - ref[None, None, 1:, X:Y + 1]).sum(axis=-1)
    dist[~present[:, 1:]] = np.inf
    dist[:, :, ~tracked[1:]] = np.inf
    pairs = np.full((b, v - 1), -1, dtype=np.int64)
    rows = np.arange(b)
    for _ in range(v - 1):
        flat = dist.reshape(b, -1).argmin(axis=1)
        i, j = np.divmod(flat, v - 1)
        ok = dist[rows, i, j] <= gate
        pairs[rows[ok], i[ok]] = j[ok]
        dist[rows[ok], i[ok], :] = np.inf
        dist[rows[ok], :, j[ok]] = np.inf
    return pairs
