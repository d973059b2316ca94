"""Simultaneous bands for values that should be uniform: the ranks of simulation-based
calibration (:mod:`brdf_infer.studies.sbc`) and the ECDF of LOO-PIT values or randomised ranks,
drawn behind their figures in the report."""

from __future__ import annotations

import numpy as np
from scipy import stats


def uniform_rank_band(replicates: int, bins: int, level: float = 0.99) -> tuple[float, float]:
    """Central ``level`` range of one bin's count under uniform ranks: Binomial(N, 1/bins)."""
    low, high = stats.binom.interval(level, replicates, 1.0 / bins)
    return float(low), float(high)


def ecdf_band(
    replicates: int, points: np.ndarray, level: float = 0.95, seed: int = 0, simulations: int = 2000
) -> tuple[np.ndarray, np.ndarray]:
    """Simultaneous ``level`` band for the ECDF of N uniform values at ``points``.

    The simulation method of Säilynoja, Bürkner & Vehtari (2022, Stat. Comput. 32, 32): find
    the pointwise level γ such that a fraction ``level`` of simulated uniform ECDFs stays inside
    every pointwise Binomial(N, z) central-(1 − γ) interval, and return those intervals (as
    fractions).
    """
    rng = np.random.default_rng(seed)
    samples = rng.uniform(size=(simulations, replicates))
    counts = np.stack([np.sum(samples <= z, axis=1) for z in points], axis=1)
    cdf = stats.binom.cdf(counts, replicates, points)
    below = stats.binom.cdf(counts - 1, replicates, points)
    tail = np.minimum(cdf, 1 - below)  # two-sided tail probability of each count
    gamma = 2 * np.quantile(np.min(tail, axis=1), 1 - level)
    low = stats.binom.ppf(gamma / 2, replicates, points) / replicates
    high = stats.binom.ppf(1 - gamma / 2, replicates, points) / replicates
    return low, high
