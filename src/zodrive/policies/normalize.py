"""Observation normalization a policy was trained with (SB3's `VecNormalize`), read without
running code, and applied inside the victim.

`VecNormalize.save` pickles the whole wrapper. A pickle can run any code, so this reader
accepts only what such a file holds (numpy arrays and scalars, the wrapper's and its running
statistics' state, the gymnasium spaces it records, numpy's random-generator state) and builds
none of SB3's or gymnasium's objects: each is read into a plain record of its state. Anything
else in the file is refused in one line.

The statistics are applied inside the victim, so the attacker keeps perturbing the
environment's observation and ε keeps its meaning (the policy sees `(obs - mean) / sqrt(var +
epsilon)`, clipped, as in training).
"""

from __future__ import annotations

import io
import pickle
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from zodrive.attacks.victim import Victim
from zodrive.errors import ZodriveError

#: file names SB3 and rl-zoo3 (`vecnormalize.pkl`) and Hugging Face model repos (`vec_normalize.pkl`) use
FILE_NAMES = ("vecnormalize.pkl", "vec_normalize.pkl")
MAX_BYTES = 64 << 20


class _State:
    """A stand-in for a class of the file: keeps the state it is given, runs nothing."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.args = args

    def __setstate__(self, state: Any) -> None:
        if isinstance(state, tuple) and len(state) == 2 and isinstance(state[1], dict):
            state = {**(state[0] or {}), **state[1]}  # (dict, slots)
        self.__dict__["state"] = state if isinstance(state, dict) else {"value": state}


def _stand_in(*args: Any, **kwargs: Any) -> _State:
    return _State(*args)


_STATE_CLASSES = {
    ("stable_baselines3.common.vec_env.vec_normalize", "VecNormalize"),
    ("stable_baselines3.common.running_mean_std", "RunningMeanStd"),
    ("gymnasium.spaces.box", "Box"), ("gymnasium.spaces.discrete", "Discrete"),
    ("gymnasium.spaces.dict", "Dict"), ("gym.spaces.box", "Box"), ("gym.spaces.discrete", "Discrete"),
    ("numpy.random.bit_generator", "SeedSequence"), ("numpy.random._pcg64", "PCG64"),
    ("numpy.random._mt19937", "MT19937"),
}
_STAND_IN_FUNCTIONS = {
    ("numpy.random._pickle", "__generator_ctor"), ("numpy.random._pickle", "__bit_generator_ctor"),
    ("numpy.random._pickle", "__randomstate_ctor"), ("numpy.random.bit_generator", "__pyx_unpickle_SeedSequence"),
}
_NUMPY = {("numpy", "dtype"), ("numpy", "ndarray"), ("numpy._core.multiarray", "_reconstruct"),
          ("numpy.core.multiarray", "_reconstruct"), ("numpy._core.multiarray", "scalar"),
          ("numpy.core.multiarray", "scalar"), ("collections", "OrderedDict")}


def _small_reconstruct(reconstruct: Any) -> Any:
    """numpy's `_reconstruct`, which allocates the shape it is asked for before the data arrives: a
    pickle asks for (0,) and fills it from its bytes; a crafted one asked for 93 GiB."""
    def guarded(subtype: Any, shape: Any, dtype: Any) -> Any:
        if not isinstance(shape, tuple) or not all(isinstance(n, int) and 0 <= n for n in shape) \
                or int(np.prod(shape, dtype=np.float64)) > MAX_BYTES:
            raise pickle.UnpicklingError(f"an array of shape {shape!r} is not part of a VecNormalize file")
        return reconstruct(subtype, shape, dtype)

    return guarded


class _Reader(pickle.Unpickler):
    def find_class(self, module: str, name: str) -> Any:
        if (module, name) in _STATE_CLASSES:
            return _State
        if (module, name) in _STAND_IN_FUNCTIONS:
            return _stand_in
        if (module, name) in _NUMPY and name == "_reconstruct":
            return _small_reconstruct(super().find_class(module, name))
        if (module, name) in _NUMPY:
            return super().find_class(module, name)
        raise pickle.UnpicklingError(f"{module}.{name} is not part of a VecNormalize file")


@dataclass(frozen=True)
class ObsNormalization:
    """`(obs - mean) / sqrt(var + epsilon)`, clipped to ±clip: what the policy saw in training."""

    mean: np.ndarray
    var: np.ndarray
    epsilon: float
    clip: float
    source: str

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return np.clip((obs - self.mean) / np.sqrt(self.var + self.epsilon), -self.clip, self.clip).astype(np.float32)

    def torch(self, obs: torch.Tensor) -> torch.Tensor:
        mean = torch.as_tensor(self.mean, dtype=obs.dtype)
        scale = torch.as_tensor(np.sqrt(self.var + self.epsilon), dtype=obs.dtype)
        return torch.clamp((obs - mean) / scale, -self.clip, self.clip)


def read_normalization(path: Path) -> ObsNormalization | None:
    """The observation statistics in a `VecNormalize` file (None: it normalizes rewards only),
    read without running code; a one-line error for anything else."""
    path = Path(path)
    if path.stat().st_size > MAX_BYTES:
        raise ZodriveError(f"{path}: {path.stat().st_size} bytes is more than a VecNormalize file holds")
    try:
        root = _Reader(io.BytesIO(path.read_bytes())).load()
    except (pickle.UnpicklingError, EOFError, ValueError, TypeError, AttributeError, IndexError, KeyError,
            MemoryError, OverflowError) as exc:
        raise ZodriveError(f"{path} is not a VecNormalize file zodrive can read without running code: {exc}") from None
    state = getattr(root, "state", None)
    if not isinstance(state, dict) or "obs_rms" not in state:
        raise ZodriveError(f"{path} is not a VecNormalize file (no observation statistics)")
    if not state.get("norm_obs", True):
        return None
    if state.get("norm_obs_keys"):
        raise ZodriveError(f"{path} normalizes a dict observation; zodrive attacks Box observations")
    rms: Any = getattr(state["obs_rms"], "state", None)  # None or a foreign object: the except below
    try:
        mean = np.asarray(rms["mean"], dtype=np.float64)
        var = np.asarray(rms["var"], dtype=np.float64)
        epsilon, clip = float(state.get("epsilon", 1e-8)), float(state.get("clip_obs", 10.0))
    except (TypeError, KeyError, ValueError):
        raise ZodriveError(f"{path}: its observation statistics are not arrays of numbers") from None
    if mean.shape != var.shape or not (np.all(np.isfinite(mean)) and np.all(np.isfinite(var)) and np.all(var >= 0)):
        raise ZodriveError(f"{path}: its observation statistics are not finite arrays of one shape")
    if not (np.isfinite(clip) and clip > 0 and np.isfinite(epsilon) and epsilon >= 0):
        raise ZodriveError(f"{path}: clip_obs {clip} / epsilon {epsilon} are not usable")
    if np.any(var + epsilon <= 0):  # (obs - mean) / 0: NaN or infinite observations, fed as if valid
        raise ZodriveError(f"{path}: {int(np.sum(var + epsilon <= 0))} features have variance 0 with epsilon 0: "
                           "the normalized observation divides by zero")
    return ObsNormalization(mean, var, epsilon, clip, str(path))


def find_normalization(model: Path) -> Path | None:
    """The VecNormalize file of the model file `model`: beside it, or in rl-zoo3's `<zip stem>/` folder
    (`<env id>.zip` beside `<env id>/vecnormalize.pkl`); another model's folder is never read."""
    folder = model.parent
    found = [base / name for base in (folder, folder / model.stem) for name in FILE_NAMES if (base / name).is_file()]
    if len(found) > 1:
        raise ZodriveError(f"{folder} holds {len(found)} normalization files ({', '.join(str(p) for p in found)}): "
                           "keep the one the model was trained with")
    return found[0] if found else None


def normalized_victim(victim: Victim, norm: ObsNormalization) -> Victim:
    """`victim` behind its training normalization: queries take the environment's observation."""
    if norm.mean.shape != tuple(victim.obs_shape):
        raise ZodriveError(f"{norm.source} normalizes observations of shape {norm.mean.shape}; the policy reads "
                           f"{tuple(victim.obs_shape)}")
    differentiable, calibrate = victim.differentiable, victim.calibrate
    return Victim(query=lambda obs: victim.query(norm(np.asarray(obs, dtype=np.float64))), kind=victim.kind,
                  obs_shape=victim.obs_shape,
                  differentiable=None if differentiable is None else (lambda obs: differentiable(norm.torch(obs))),
                  calibrate=None if calibrate is None
                  else (lambda obs: calibrate(norm(np.asarray(obs, dtype=np.float64)))))
