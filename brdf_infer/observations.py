"""Observation model: parameters → predicted ln R of each measurement row (Eqs. 6, 7, 10).

Assembled from a scene: only what the scene uses is computed (folding only when the scene
turns it on).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from brdf_infer._units import DEG
from brdf_infer.error_model import noise_layout
from brdf_infer.measurements import Measurements
from brdf_infer.model import log_aperture_factor, log_brdf_inplane
from brdf_infer.params import HemisphereConstants, Params
from brdf_infer.scene import Scene


class Observations(NamedTuple):
    """Per-row arrays (a pytree).

    Attributes:
        theta_i_deg: θi [deg].
        theta_s_deg: θs [deg].
        log_aperture: ln(Ω cos θs) of the row's series [ln sr].
        log_reflectance: measured ln R.
        sigma: 1σ of ln R that weights the row in least squares (``brdf_infer.lsq``).
    """

    theta_i_deg: jnp.ndarray
    theta_s_deg: jnp.ndarray
    log_aperture: jnp.ndarray
    log_reflectance: jnp.ndarray
    sigma: jnp.ndarray


def predicted_log_reflectance(
    params: Params, data: Observations, fold: bool, constants: HemisphereConstants
) -> jnp.ndarray:
    """ln R of every row: ln BRDF(θi, θs) of Eq. (7) (+ Eq. 10) + ln(Ω cos θs), Eq. (6)."""
    log_brdf = log_brdf_inplane(data.theta_i_deg, data.theta_s_deg, params, fold, constants)
    return log_brdf + data.log_aperture


def log_reflectance_at(
    theta_i_deg, theta_s_deg, params: Params, fold: bool, constants: HemisphereConstants
) -> jnp.ndarray:
    """ln R(θi, θs) up to the constant ln Ω: ln BRDF + ln cos θs (for the angle slopes)."""
    log_brdf = log_brdf_inplane(theta_i_deg, theta_s_deg, params, fold, constants)
    return log_brdf + jnp.log(jnp.cos(jnp.asarray(theta_s_deg, float) * DEG))


def standardized_residuals(
    params: Params, data: Observations, fold: bool, constants: HemisphereConstants
) -> jnp.ndarray:
    """(ln R_pred − ln R_obs)/σ of every row."""
    return (predicted_log_reflectance(params, data, fold, constants) - data.log_reflectance) / (
        data.sigma
    )


@dataclass(frozen=True)
class ObservationModel:
    """Predicts ln R for a scene's rows; the one prediction kernel of every fit and sampler.

    Attributes:
        data: the rows (``sigma``: each row's own noise, before any fit adds to it).
        fold: apply Eq. (10) on the forward side.
        constants: folding constants.
    """

    data: Observations
    fold: bool
    constants: HemisphereConstants

    @property
    def n_points(self) -> int:
        return int(self.data.theta_i_deg.shape[0])

    def log_reflectance(self, params: Params) -> jnp.ndarray:
        """Predicted ln R = ln BRDF(θi, θs) + ln(Ω cos θs), Eq. (6) in log space."""
        return predicted_log_reflectance(params, self.data, self.fold, self.constants)

    def residuals(self, params: Params) -> jnp.ndarray:
        """Standardised residuals (ln R_pred − ln R_obs)/σ."""
        return standardized_residuals(params, self.data, self.fold, self.constants)

    def chi2(self, params: Params) -> jnp.ndarray:
        """χ² = Σ residuals²."""
        return jnp.sum(self.residuals(params) ** 2)

    def with_sigma(self, sigma) -> ObservationModel:
        """The same rows weighted by other σ."""
        return ObservationModel(
            self.data._replace(sigma=jnp.asarray(sigma)), self.fold, self.constants
        )


def build_observation_model(scene: Scene, measurements: Measurements) -> ObservationModel:
    """The observation model of ``scene`` on ``measurements`` (every row, each sample).

    ``sigma`` is each row's fixed noise under the scene's error model (for ``generative``, the
    value's own σ_i; ``brdf_infer.lsq`` adds the per-row scatter and the angle terms).
    """
    d, r = scene.apertures(measurements)
    data = Observations(
        theta_i_deg=jnp.asarray(measurements.theta_i_deg),
        theta_s_deg=jnp.asarray(measurements.theta_s_deg),
        log_aperture=log_aperture_factor(measurements.theta_s_deg, d, r),
        log_reflectance=jnp.asarray(np.log(measurements.reflectance)),
        sigma=noise_layout(scene.errors, measurements).sigma_row,
    )
    return ObservationModel(data, scene.model.fold, scene.model.constants)
