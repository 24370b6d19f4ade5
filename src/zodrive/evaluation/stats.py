"""Statistics for reports (scipy): bootstrap CIs of means, Wilson CIs of per-episode rates,
and episode-resampling CIs of per-step rates."""

from __future__ import annotations

from typing import Sequence

import numpy as np
from scipy import stats


def mean_ci(values: Sequence[float] | np.ndarray, *, confidence: float = 0.95, seed: int = 0) -> tuple[float, float]:
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


def ratio_ci(
    numerators: Sequence[float], denominators: Sequence[float], *, confidence: float = 0.95, seed: int = 0
) -> tuple[float, float]:
    """CI of sum(numerators) / sum(denominators), resampling whole episodes (a cluster
    bootstrap, percentile, 10,000 resamples, fixed seed).

    For per-step rates such as attack success: the steps of one episode are correlated
    (the same traffic, the same victim state), so treating thousands of steps as
    independent trials (Wilson) would give a CI far too narrow. Episodes are independent."""
    num = np.asarray(numerators, dtype=np.float64)
    den = np.asarray(denominators, dtype=np.float64)
    if den.sum() == 0:
        return (float("nan"), float("nan"))
    rate = float(num.sum() / den.sum())
    if num.size == 1:
        return (rate, rate)

    def statistic(n: np.ndarray, d: np.ndarray, axis: int = -1) -> np.ndarray:
        total = d.sum(axis=axis)
        return np.divide(n.sum(axis=axis), total, out=np.zeros_like(total), where=total > 0)

    res = stats.bootstrap(
        (num, den), statistic, paired=True, vectorized=True, confidence_level=confidence,
        n_resamples=10_000, method="percentile", random_state=np.random.default_rng(seed),
    )
    return (float(res.confidence_interval.low), float(res.confidence_interval.high))


def paired_difference_ci(a: Sequence[float], b: Sequence[float], *, seed: int = 0) -> tuple[float, float, float]:
    """Mean of a - b over paired episodes (same seeds) with its bootstrap CI."""
    diff = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    low, high = mean_ci(diff, seed=seed)
    return float(diff.mean()), low, high


def iqm_over_seeds(returns: Sequence[Sequence[float]], *, reps: int = 10_000,
                   seed: int = 0) -> tuple[float, float, float] | None:
    """Interquartile mean over training seeds x evaluation episodes with a stratified
    bootstrap 95 % CI (rliable: Agarwal et al., "Deep RL at the Edge of the Statistical
    Precipice", NeurIPS 2021): runs are the seeds, tasks the evaluation episodes (every
    seed sees the same episodes). None when rliable (`zodrive[stats]`) is not installed."""
    try:
        from rliable import library as rly
        from rliable import metrics
    except ImportError:
        return None
    scores = np.asarray(returns, dtype=np.float64)  # (seeds, episodes)
    np.random.seed(seed)  # rliable draws from numpy's global generator
    point, interval = rly.get_interval_estimates({"agent": scores}, lambda x: np.array([metrics.aggregate_iqm(x)]),
                                                 reps=reps)
    return float(point["agent"][0]), float(interval["agent"][0, 0]), float(interval["agent"][1, 0])
