"""Uniform random noise inside the budget: the floor every real attack must beat.

No optimization: one draw, uniform in the L-inf box (or L2 ball) of radius eps, masked and
clipped. It queries only to report its effect.

Queries per environment step: 2 (the clean observation and the noisy one).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from zodrive.attacks.base import Attack, reads_all_but
from zodrive.attacks.threat import ThreatModel


class UniformNoise(Attack):
    name = "uniform-noise"
    reference = "baseline (no paper): uniform noise in the threat model"
    on_decisions = True  # what it feeds reads no output; its success is read from the decision

    reads = reads_all_but("steps", "n_directions", "mu", "step_size", "patience")

    def __init__(self, threat: ThreatModel, **kwargs: Any) -> None:
        super().__init__(threat, **kwargs)
        self.steps = 1  # one draw, queried once

    def queries_per_run(self, steps: int | None = None) -> int:
        return 2

    def init(self, x0: np.ndarray, mask: np.ndarray) -> np.ndarray:
        dim = x0.shape[1]
        return x0 + self.draw(np.arange(len(x0)), lambda g: self.threat.random_delta((1, dim), mask, g)[0])

    def step(self, k: int, cand: np.ndarray, f: np.ndarray, rows: np.ndarray, grad: np.ndarray | None) -> np.ndarray:
        raise AssertionError("uniform noise takes no step")  # steps = 1: the driver never asks
