"""The threat model: what the attacker may change in an observation, and by how much."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, Sequence

import numpy as np

from zodrive.errors import ZodriveError

Norm = Literal["linf", "l2"]
Mode = Literal["budgeted", "paper"]


@dataclass(frozen=True)
class ThreatModel:
    """An Lp budget in normalized observation units, a feature mask and a box.

    `mode="budgeted"` projects every candidate onto the eps-ball (the default);
    `mode="paper"` leaves the perturbation unconstrained, as published, and only reports
    its size. Either way the result is clipped to [low, high] and masked features
    (by default `presence`) are never changed.
    """

    eps: float = 0.2                      # [normalized units] 0.2 = 10 % of [-1, 1]
    norm: Norm = "linf"
    mode: Mode = "budgeted"
    frozen: tuple[str, ...] = ("presence",)
    features: tuple[str, ...] = ("presence", "x", "y", "vx", "vy")
    low: float = -1.0
    high: float = 1.0
    _mask_cache: dict = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        if not np.isfinite(self.eps) or self.eps <= 0:
            raise ZodriveError(f"eps must be > 0, not {self.eps}")
        if self.norm not in ("linf", "l2"):
            raise ZodriveError(f"norm must be linf or l2, not {self.norm!r}")
        if self.mode not in ("budgeted", "paper"):
            raise ZodriveError(f"mode must be budgeted or paper, not {self.mode!r}")
        unknown = set(self.frozen) - set(self.features)
        if unknown:
            raise ZodriveError(f"frozen features {sorted(unknown)} are not observation features")

    def mask(self, obs_shape: Sequence[int]) -> np.ndarray:
        """1.0 where the attacker may write, 0.0 on frozen features (last axis)."""
        key = tuple(obs_shape)
        if key not in self._mask_cache:
            mask = np.ones(key, dtype=np.float32)
            if len(key) >= 1 and key[-1] == len(self.features):
                for name in self.frozen:
                    mask[..., self.features.index(name)] = 0.0
            self._mask_cache[key] = mask
        return self._mask_cache[key]

    def project(self, x: np.ndarray, x0: np.ndarray) -> np.ndarray:
        """Map candidates `x` (B, *obs) around clean `x0` (B, *obs) into the threat model."""
        delta = (x - x0) * self.mask(x0.shape[1:])
        if self.mode == "budgeted":
            if self.norm == "linf":
                delta = np.clip(delta, -self.eps, self.eps)
            else:
                flat = delta.reshape(len(delta), -1)
                norms = np.linalg.norm(flat, axis=1)
                scale = np.minimum(1.0, self.eps / np.maximum(norms, 1e-12))
                delta = (flat * scale[:, None]).reshape(delta.shape)
        return np.clip(x0 + delta, self.low, self.high).astype(x0.dtype, copy=False)

    def random_delta(self, x0: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """A uniform draw from the budget set (L-inf box or L2 ball), masked."""
        shape = x0.shape
        if self.norm == "linf":
            delta = rng.uniform(-self.eps, self.eps, size=shape)
        else:
            flat = rng.standard_normal((shape[0], int(np.prod(shape[1:]))))
            flat /= np.linalg.norm(flat, axis=1, keepdims=True)
            radius = self.eps * rng.uniform(size=(shape[0], 1)) ** (1.0 / flat.shape[1])
            delta = (flat * radius).reshape(shape)
        return (delta * self.mask(shape[1:])).astype(x0.dtype)


def distortion(x: np.ndarray, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-row L-inf and L2 size of `x - x0`."""
    flat = (x - x0).reshape(len(x), -1).astype(np.float64)
    return np.abs(flat).max(axis=1), np.linalg.norm(flat, axis=1)
