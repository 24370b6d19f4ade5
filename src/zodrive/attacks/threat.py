"""The threat model: what the attacker may change in an observation, and by how much."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Literal, Sequence

import numpy as np

from zodrive.errors import ZodriveError

if TYPE_CHECKING:
    import torch

Norm = Literal["linf", "l2"]
Mode = Literal["budgeted", "paper"]


@dataclass(frozen=True)
class ThreatModel:
    """An Lp budget in normalized observation units, a feature mask and a box.

    `mode="budgeted"` projects every candidate onto the eps-ball (the default);
    `mode="paper"` leaves the perturbation unconstrained, as published, and only reports
    its size. Either way every point the attacker queries or feeds is kept inside the
    observation box [low, high] (the values a real sensor can produce: the preset's
    normalization range, the observation space's box per dimension, or unbounded; `low` and
    `high` are numbers or, per dimension, the flattened box), the features are named along
    `feature_axis` (the last for Kinematics, the first for OccupancyGrid), masked features (by
    default `presence`) are never changed, and a clean coordinate is never moved by the box: a
    clean value outside it stays reachable. Where a guarantee cannot hold (a frozen feature the observation does
    not have), `mask` raises instead of skipping it.

    `vehicles` (None: every row) makes the budget sparse in space: a point differs from the clean
    observation in at most that many rows of a Kinematics observation (one row per vehicle, the ego's
    first, features along the last axis). The projection keeps the rows whose change (after the mask,
    the ball and the box) has the largest L2 norm, the lower row on a tie, and sets the others back to
    their clean values; a point that already moves at most that many rows is left as it is.
    """

    eps: float = 0.2                      # [normalized units] 0.2 = 10 % of [-1, 1]
    norm: Norm = "linf"
    mode: Mode = "budgeted"
    frozen: tuple[str, ...] = ("presence",)
    features: tuple[str, ...] = ("presence", "x", "y", "vx", "vy")
    low: float | tuple[float, ...] = -1.0  # observation box (the preset's range, or per dimension)
    high: float | tuple[float, ...] = 1.0
    feature_axis: int = -1                 # the observation axis the features are named along
    vehicles: int | None = None            # at most this many rows (vehicles) perturbed; None: every row
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
        low, high = np.asarray(self.low, dtype=np.float64), np.asarray(self.high, dtype=np.float64)
        if low.shape != high.shape or not np.all(low < high):
            raise ZodriveError(f"observation box [{self.low}, {self.high}] is empty")
        if self.vehicles is not None and self.vehicles < 1:
            raise ZodriveError(f"vehicles must be >= 1, not {self.vehicles}")

    def vehicle_rows(self, obs_shape: Sequence[int]) -> int:
        """The vehicle rows of observations of `obs_shape` that `vehicles` counts: a 2-D observation whose
        named features run along its last axis (Kinematics); anything else has none, and is refused."""
        shape = tuple(obs_shape)
        if not (len(shape) == 2 and self.features and self.feature_axis in (-1, 1) and shape[1] == len(self.features)):
            raise ZodriveError(f"vehicles counts the rows of a Kinematics observation (one per vehicle, features "
                               f"along the last axis); observations of shape {shape} have none: drop --vehicles")
        return shape[0]

    def box(self, dim: int) -> tuple[np.ndarray, np.ndarray]:
        """The observation box as two (dim,) arrays for flattened observations of `dim` values."""
        low, high = np.asarray(self.low, dtype=np.float32), np.asarray(self.high, dtype=np.float32)
        if low.ndim and low.size != dim:
            raise ZodriveError(f"the observation box has {low.size} values per bound, the observation {dim}")
        return np.broadcast_to(low.reshape(-1), (dim,)), np.broadcast_to(high.reshape(-1), (dim,))

    def mask(self, obs_shape: Sequence[int]) -> np.ndarray:
        """1.0 where the attacker may write, 0.0 on frozen features (along `feature_axis`)."""
        key = tuple(obs_shape)
        if key not in self._mask_cache:
            mask = np.ones(key, dtype=np.float32)
            axis = self.feature_axis
            if self.frozen and not (-len(key) <= axis < len(key) and key[axis] == len(self.features)):
                raise ZodriveError(
                    f"cannot freeze {', '.join(self.frozen)}: observations of shape {key} do not have the "
                    f"{len(self.features)} features {', '.join(self.features)} along axis {axis}"
                )
            for name in self.frozen:
                index: list[Any] = [slice(None)] * len(key)
                index[axis] = self.features.index(name)
                mask[tuple(index)] = 0.0
            self._mask_cache[key] = mask
        return self._mask_cache[key]

    def project(self, x: np.ndarray, x0: np.ndarray) -> np.ndarray:
        """Map candidates `x` (B, *obs) around clean `x0` (B, *obs) into the threat model."""
        n = len(x0)
        around = self.around(x0.reshape(n, -1), x0.shape[1:], integer=np.issubdtype(x0.dtype, np.integer))
        return around(x.reshape(n, 1, -1), np.arange(n)).reshape(x0.shape).astype(x0.dtype, copy=False)

    def around(self, x0: np.ndarray, obs_shape: Sequence[int], integer: bool = False) -> Projector:
        """`project` around the flattened clean rows `x0` (N, dim) of observations of
        `obs_shape`, their box computed once (an attack projects around them every iteration);
        `integer`: the sensor gives integers (pixels), so every projected point is whole."""
        rows = None if self.vehicles is None else self.vehicle_rows(obs_shape)
        return Projector(self, x0, self.mask(obs_shape).reshape(-1), integer, rows)

    def random_delta(self, shape: tuple[int, ...], mask: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Uniform draws (shape = (N, dim)) from the budget set (L-inf box or L2 ball) on the
        free coordinates (`mask`, (dim,)); radius eps in both modes."""
        n, dim = shape
        if self.norm == "linf":
            delta = rng.uniform(-self.eps, self.eps, size=shape)
        else:
            free = max(int(mask.sum()), 1)
            flat = rng.standard_normal(shape) * mask
            flat /= np.maximum(np.linalg.norm(flat, axis=1, keepdims=True), 1e-12)
            delta = flat * self.eps * rng.uniform(size=(n, 1)) ** (1.0 / free)
        return (delta * mask).astype(np.float32)


class Projector:
    """`ThreatModel.project` around fixed clean rows: candidates (A, M, dim) of rows `rows`
    into the threat model, by the same arithmetic as `project` (broadcast, not repeated); with
    `threat.vehicles`, the flat points are `vehicle_rows` rows of features each."""

    def __init__(self, threat: ThreatModel, x0: np.ndarray, mask: np.ndarray, integer: bool = False,
                 vehicle_rows: int | None = None) -> None:
        self.threat, self.x0, self.mask, self.integer = threat, x0, mask, integer
        self.vehicle_rows = vehicle_rows
        low, high = threat.box(x0.shape[1])
        self.low, self.high = np.minimum(low, x0), np.maximum(high, x0)  # never move a clean value

    def __call__(self, x: np.ndarray, rows: np.ndarray) -> np.ndarray:
        t = self.threat
        # rows are distinct indices: as many as there are clean rows means all of them, in order
        every = len(rows) == len(self.x0)
        x0, low, high = (self.x0, self.low, self.high) if every else (self.x0[rows], self.low[rows], self.high[rows])
        x0 = x0[:, None]
        delta = np.subtract(x, x0)
        delta *= self.mask
        if t.mode == "budgeted":
            if t.norm == "linf":
                delta = np.clip(delta, -t.eps, t.eps, out=delta)
            else:
                norms = np.linalg.norm(delta, axis=-1, keepdims=True)
                delta = delta * np.minimum(1.0, t.eps / np.maximum(norms, 1e-12))
        delta += x0
        inside = np.clip(delta, low[:, None], high[:, None], out=delta)
        if self.integer:  # pixels: each change rounded toward the clean value stays in the ball and the box,
            inside -= x0  # and the point queried is the point fed (nothing is rounded after the search)
            np.trunc(inside, out=inside)
            inside += x0
        if self.vehicle_rows is not None and t.vehicles is not None and t.vehicles < self.vehicle_rows:
            inside = self._sparse(inside, x0, t.vehicles)
        return inside

    def _sparse(self, x: np.ndarray, x0: np.ndarray, k: int) -> np.ndarray:
        """Points (A, M, dim) around clean rows x0 (A, 1, dim) with every vehicle row but the k it moved most
        (L2 norm of the row's change; the lower row on a tie) set back to clean."""
        rows = self.vehicle_rows
        assert rows is not None
        change = (x - x0).reshape(*x.shape[:-1], rows, -1).astype(np.float64)
        size = np.einsum("...f,...f->...", change, change)
        order = np.argsort(-size, axis=-1, kind="stable")  # the largest first, ties in row order
        keep = np.zeros(size.shape, dtype=bool)
        np.put_along_axis(keep, order[..., :k], True, axis=-1)
        keep &= size > 0
        per_value = np.repeat(keep, x.shape[-1] // rows, axis=-1)
        return np.where(per_value, x, np.broadcast_to(x0, x.shape)).astype(x.dtype, copy=False)


def distortion(x: np.ndarray, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-row L-inf and L2 size of `x - x0`."""
    if np.issubdtype(np.asarray(x).dtype, np.integer):  # pixels: subtracted as integers, -3 would wrap to 253
        x, x0 = np.asarray(x, dtype=np.float64), np.asarray(x0, dtype=np.float64)
    flat = (x - x0).reshape(len(x), -1).astype(np.float64)
    return np.abs(flat).max(axis=1), np.linalg.norm(flat, axis=1)


def worst_in_ball(objective: Callable[[torch.Tensor], torch.Tensor], x0: torch.Tensor, eps: float, steps: int,
                  mask: torch.Tensor | float, low: float, high: float) -> torch.Tensor:
    """WHITE-BOX, for robust training: the point of the L-inf eps-ball around the torch batch
    `x0` where `objective(x)` (per row, summed) is highest, by PGD (Madry et al., ICLR 2018):
    a random start, then `steps` signed-gradient steps of 2.5 eps / steps. The same threat
    model as the attacks: the box [low, high] (a clean value outside it stays reachable) and
    `mask` (0 on frozen features, broadcast over the batch). Returns a detached tensor."""
    import torch

    lo = torch.minimum(torch.clamp(x0 - eps, min=low), x0)
    hi = torch.maximum(torch.clamp(x0 + eps, max=high), x0)
    x = torch.max(torch.min(x0 + (torch.rand_like(x0) * 2 - 1) * eps * mask, hi), lo)
    step = 2.5 * eps / max(steps, 1)
    for _ in range(steps):
        x = x.detach().requires_grad_(True)
        grad, = torch.autograd.grad(objective(x).sum(), x)
        x = torch.max(torch.min(x.detach() + step * grad.sign() * mask, hi), lo)
    return x.detach()
