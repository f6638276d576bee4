"""Aggregate statistics over seeds: interquartile mean and percentile-bootstrap confidence intervals
(the rliable recipe, Agarwal et al. 2021, computed with NumPy/SciPy)."""

from __future__ import annotations

import numpy as np
from scipy import stats


def iqm(values: np.ndarray) -> float:
    """Interquartile mean: the mean of the middle 50 % (SciPy's trimmed mean, 25 % cut each side)."""
    return float(stats.trim_mean(np.asarray(values, dtype=float), proportiontocut=0.25))


def bootstrap_ci(
    values: np.ndarray, statistic=np.mean, *, reps: int = 2000, confidence: float = 0.95, seed: int = 0
) -> tuple[float, float]:
    """Percentile bootstrap CI of `statistic` over resampled values (seeds)."""
    values = np.asarray(values, dtype=float)
    if len(values) == 1:
        return float(values[0]), float(values[0])
    rng = np.random.default_rng(seed)
    samples = values[rng.integers(0, len(values), size=(reps, len(values)))]
    estimates = np.array([statistic(s) for s in samples])
    alpha = (1.0 - confidence) / 2.0
    return float(np.quantile(estimates, alpha)), float(np.quantile(estimates, 1.0 - alpha))


def mean_ci_curve(curves: np.ndarray, *, reps: int = 1000, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean over seeds and 95 % bootstrap band per point of (seeds, points) curves."""
    curves = np.asarray(curves, dtype=float)
    mean = curves.mean(axis=0)
    if curves.shape[0] == 1:
        return mean, mean, mean
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, curves.shape[0], size=(reps, curves.shape[0]))
    boot = curves[idx].mean(axis=1)  # (reps, points)
    return mean, np.quantile(boot, 0.025, axis=0), np.quantile(boot, 0.975, axis=0)
