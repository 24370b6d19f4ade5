"""Small victims with known structure, for fast attack tests (no highway-env)."""

from __future__ import annotations

import json
import tempfile
from functools import lru_cache
from pathlib import Path

import numpy as np
import torch

from zodrive.attacks.victim import Victim

FEATURES = ("presence", "x", "y", "vx", "vy")
CONTEXT = {"features": FEATURES, "bounds": (-1.0, 1.0), "n_actions": 5}  # the discrete preset


def context(kind: str = "discrete") -> dict:
    """`AttackSpec.build` arguments for a toy victim of this kind."""
    return {**CONTEXT, "n_actions": 5 if kind == "discrete" else 2}


def readable(name: str, **options):
    """`options` without those attack `name` does not read (`Attack.reads`), which it would refuse: one set of
    options for a test that runs every attack."""
    from zodrive.attacks.base import TUNABLE
    from zodrive.attacks.registry import ATTACKS

    return {k: v for k, v in options.items() if k not in TUNABLE or k in ATTACKS[name].reads}


def linear_victim(seed: int = 0, kind: str = "discrete", hidden: int = 16) -> Victim:
    """A small tanh MLP over (5, 5) observations: 5 Q-values or a 2-d action in [-1, 1]."""
    gen = torch.Generator().manual_seed(seed)
    out = 5 if kind == "discrete" else 2
    # weights laid out (out, in) as nn.Linear's: a row's outputs do not depend on where it sits in a batch
    w1 = (torch.randn(25, hidden, generator=gen) * 0.8).T.contiguous()
    w2 = (torch.randn(hidden, out, generator=gen) * 0.8).T.contiguous()
    return _mlp_victim(w1, w2, kind)


def portable_victim(seed: int = 0, kind: str = "discrete", hidden: int = 16) -> Victim:
    """`linear_victim`'s network with arithmetic that does not depend on the CPU: weights drawn by numpy
    (torch's randn of 16 or more numbers takes a vectorized path that differs between instruction sets),
    computed in float64 and rounded to a 2**-16 grid (straight through, so white-box gradients stay), so
    that one input gives the same output bits on any x86 machine. For digests of whole attack runs."""
    rng = np.random.default_rng(seed)
    out = 5 if kind == "discrete" else 2
    w1 = torch.from_numpy(rng.standard_normal((hidden, 25)) * 0.8)
    w2 = torch.from_numpy(rng.standard_normal((out, hidden)) * 0.8)
    return _mlp_victim(w1, w2, kind, grid=2**16)


def _mlp_victim(w1: torch.Tensor, w2: torch.Tensor, kind: str, grid: float | None = None) -> Victim:
    """tanh(x W1) W2 (tanh again for a continuous action) in the weights' dtype, float32 out; `grid`
    rounds the outputs to multiples of 1/grid."""
    linear = torch.nn.functional.linear

    def forward(x: torch.Tensor) -> torch.Tensor:
        y = linear(torch.tanh(linear(x.reshape(-1, 25).to(w1.dtype), w1)), w2)
        y = torch.tanh(y) if kind == "continuous" else y
        if grid is not None:
            y = y + (torch.round(y * grid) / grid - y).detach()
        return y.float()

    def query(x: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return forward(torch.from_numpy(np.asarray(x, dtype=np.float32))).numpy()

    # a network the test built itself: the harness may calibrate on it (as on zodrive's own copy of a model)
    return Victim(query=query, kind=kind, obs_shape=(5, 5), differentiable=forward, calibrate=query)


def observations(n: int, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x = rng.uniform(-0.6, 0.6, size=(n, 5, 5)).astype(np.float32)
    x[:, :, 0] = 1.0  # presence
    return x


def counting_victim(calls: list[int]) -> Victim:
    """`linear_victim()` that appends the batch size of every call to `calls`."""
    base = linear_victim()

    def counted(x: np.ndarray) -> np.ndarray:
        calls.append(len(x))
        return base.query(x)

    return Victim(query=counted, kind="discrete", obs_shape=(5, 5), calibrate=base.calibrate)  # calibration uncounted


@lru_cache(maxsize=None)
def blind_picker(eps: float) -> str:
    """A picker folder (`vertex-check:DIR`) that rates every vertex alike and ranks one candidate: vertex
    check with it draws its fresh vertices as blind vertex check did (the same random numbers), for FASTER
    (index 3) at `eps` with `presence` frozen."""
    from zodrive.attacks.picker import FORMAT, META_FILE, WEIGHTS_FILE, network

    folder = Path(tempfile.mkdtemp(prefix="blind-picker-"))
    net = network(25, 1)
    with torch.no_grad():
        for p in net.parameters():
            p.zero_()
    torch.save(net.state_dict(), folder / WEIGHTS_FILE)
    meta = {"format": FORMAT, "victim": "toy", "victim_sha256": "-", "preset": {}, "eps": eps, "norm": "linf",
            "frozen": ["presence"], "target": 3, "tol": None, "obs_shape": [5, 5], "width": 1, "candidates": 1,
            "switch": 0.0}
    (folder / META_FILE).write_text(json.dumps(meta))
    return str(folder)


def logging_victim(victim: Victim, log: list[np.ndarray]) -> Victim:
    """`victim` that logs every batch it is asked about (calibration apart)."""

    def query(x: np.ndarray) -> np.ndarray:
        log.append(np.array(x, copy=True))
        return np.asarray(victim.query(x))

    return Victim(query=query, kind=victim.kind, obs_shape=victim.obs_shape, differentiable=victim.differentiable,
                  calibrate=victim.calibrate)
