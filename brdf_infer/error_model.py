"""The error model shared by the least-squares fit and the posterior.

Residuals live in ln R (raw reflectance). Row i has the 1σ

    σᵢ² = σ_rel² + s(θi)²,

where σ_rel is the scene's relative reflectance uncertainty (6.5 % for Lyman-α) and s(θi) the
inter-sample spread: the standard deviation of ln R over the samples measured at one geometry
(series, θi, θs), pooled per θi, and interpolated in θi (constant beyond the ends) for rows at
incidence angles with a single sample.
"""

from __future__ import annotations

import numpy as np

from brdf_infer.errors import BadInputError
from brdf_infer.measurements import Measurements


def inter_sample_spread(measurements: Measurements) -> np.ndarray:
    """s(θi) of every row: std of ln R over samples (ddof = 1), interpolated in θi.

    Returns zeros when no geometry was measured on two or more samples.
    """
    log_r = np.log(measurements.reflectance)
    keys = list(
        zip(measurements.series, measurements.theta_i_deg, measurements.theta_s_deg, strict=True)
    )
    variances: dict[float, list[float]] = {}
    for key in dict.fromkeys(keys):
        rows = np.array([k == key for k in keys])
        if len(set(measurements.sample[rows])) >= 2:
            variances.setdefault(float(key[1]), []).append(float(np.var(log_r[rows], ddof=1)))
    if not variances:
        return np.zeros(len(measurements))
    angles = np.array(sorted(variances))
    spreads = np.sqrt([np.mean(variances[a]) for a in angles])
    return np.interp(measurements.theta_i_deg, angles, spreads)


def log_reflectance_sigma(reflectance_rel: float, measurements: Measurements) -> np.ndarray:
    """σᵢ of ln R for every row: √(σ_rel² + s(θi)²).

    Raises:
        BadInputError: when some σᵢ is zero (no relative uncertainty and no spread).
    """
    sigma = np.sqrt(reflectance_rel**2 + inter_sample_spread(measurements) ** 2)
    if np.any(sigma <= 0):
        raise BadInputError(
            "the error model gives zero uncertainty: set errors.reflectance_rel > 0",
            file=measurements.path,
            field="errors.reflectance_rel",
        )
    return sigma
