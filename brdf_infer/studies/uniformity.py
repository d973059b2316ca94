"""Simultaneous bands for values that should be uniform: the ranks of simulation-based
calibration (:mod:`brdf_infer.studies.sbc`) and the ECDF of LOO-PIT values or randomised ranks,
drawn behind their figures in the report."""

from __future__ import annotations

import numpy as np
from scipy import stats

from brdf_infer._internal import arviz as az


def uniform_rank_band(replicates: int, bins: int, level: float = 0.99) -> tuple[float, float]:
    """Central ``level`` range of one bin's count under uniform ranks: Binomial(N, 1/bins)."""
    low, high = stats.binom.interval(level, replicates, 1.0 / bins)
    return float(low), float(high)


def ecdf_band(
    replicates: int, points: np.ndarray, level: float = 0.95, seed: int = 0, simulations: int = 2000
) -> tuple[np.ndarray, np.ndarray]:
    """Simultaneous ``level`` band for the ECDF of N uniform values at ``points`` (fractions).

    ArviZ's simulation method (Säilynoja, Bürkner & Vehtari 2022, Stat. Comput. 32, 32): the
    pointwise level γ such that a fraction ``level`` of ``simulations`` uniform ECDFs stays
    inside every pointwise Binomial(N, z) central-(1 − γ) interval, and those intervals. The
    simulation rather than ArviZ's optimised default, whose cost grows faster with N: a whole
    table's LOO-PIT has N in the 10⁴s.
    """
    return az.ecdf_confidence_band(
        replicates,
        points,
        points,
        prob=level,
        method="simulated",
        rvs=_uniform,
        num_trials=simulations,
        random_state=np.random.default_rng(seed),
    )


def _uniform(size: int, random_state: np.random.Generator | None = None) -> np.ndarray:
    """Uniform(0, 1) values, the reference distribution of the band."""
    return stats.uniform.rvs(size=size, random_state=random_state)
