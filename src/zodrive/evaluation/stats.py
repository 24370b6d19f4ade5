"""Statistics for reports: bootstrap CIs of means and Wilson CIs of rates (scipy)."""

from __future__ import annotations

from typing import Sequence

import numpy as np
from scipy import stats


def mean_ci(values: Sequence[float], *, confidence: float = 0.95, seed: int = 0) -> tuple[float, float]:
    """Bootstrap (BCa, 10,000 resamples, fixed seed) CI of the mean; degenerate -> [m, m]."""
    data = np.asarray(values, dtype=np.float64)
    if data.size == 0:
        return (float("nan"), float("nan"))
    if data.size == 1 or np.ptp(data) == 0:
        return (float(data.mean()), float(data.mean()))
    res = stats.bootstrap(
        (data,), np.mean, confidence_level=confidence, n_resamples=10_000,
        method="BCa", random_state=np.random.default_rng(seed),
    )
    low, high = res.confidence_interval
    if not (np.isfinite(low) and np.isfinite(high)):  # BCa can fail on near-constant data
        low, high = np.percentile(data, [(1 - confidence) / 2 * 100, (1 + confidence) / 2 * 100])
    return (float(low), float(high))


def rate_ci(successes: int, trials: int, *, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval of a proportion."""
    if trials == 0:
        return (float("nan"), float("nan"))
    ci = stats.binomtest(int(successes), int(trials)).proportion_ci(confidence, method="wilson")
    return (float(ci.low), float(ci.high))


def paired_difference_ci(a: Sequence[float], b: Sequence[float], *, seed: int = 0) -> tuple[float, float, float]:
    """Mean of a - b over paired episodes (same seeds) with its bootstrap CI."""
    diff = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    low, high = mean_ci(diff, seed=seed)
    return float(diff.mean()), low, high
