"""Observation model: parameters → predicted ln R of each measurement row (Eqs. 6, 7, 10),
for every model family along one path (:func:`log_reflectance`).

Assembled from a scene: only what the scene uses is computed (folding only when the scene
turns it on).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from brdf_infer._internal.units import DEG
from brdf_infer.instrument import Kernel, build_kernel, kernel_log_reflectance
from brdf_infer.model import ModelFamily, Physical, strumik_family
from brdf_infer.model.error_model import noise_layout
from brdf_infer.model.params import HemisphereConstants, Params
from brdf_infer.scene import Scene
from brdf_infer.tables.measurements import Measurements


class Observations(NamedTuple):
    """Per-row arrays (a pytree).

    Attributes:
        theta_i_deg: θi [deg].
        theta_s_deg: θs [deg].
        theta_s_deg: θs [deg]: signed in the plane of incidence, the polar angle for rows out
            of it.
        log_aperture: ln(measured value / BRDF): ln(Ω cos θs) of the row's series for raw
            reflectance, 0 for BRDF rows [ln sr].
        log_reflectance: measured ln R (ln BRDF for BRDF rows).
        sigma: 1σ of ln R that weights the row in least squares (``brdf_infer.fit.lsq``).
        cos_weight: 1 where the measured value carries cos θs (raw reflectance), 0 for BRDF.
        phi_s_deg: azimuth of out-of-plane rows [deg], NaN in the plane; None when every row
            is in the plane (nothing out of plane is computed then).
        kernel: the instrument kernel of the rows (``aperture`` or ``image``), None for the
            ``point`` instrument of Eq. (6).
    """

    theta_i_deg: jnp.ndarray
    theta_s_deg: jnp.ndarray
    log_aperture: jnp.ndarray
    log_reflectance: jnp.ndarray
    sigma: jnp.ndarray
    cos_weight: jnp.ndarray
    phi_s_deg: jnp.ndarray | None = None
    kernel: Kernel | None = None


def log_reflectance(member: ModelFamily, physical: Physical, data: Observations) -> jnp.ndarray:
    """ln R of every row under the family ``member``, the one forward path of every fit, the
    posterior, the simulations and the predictions: ln BRDF of the row (in the plane at a
    signed θs, Eq. 8 out of it) + ln(Ω cos θs), Eq. (6); ln BRDF itself for BRDF rows; with a
    kernel, ln Σ w_k BRDF_k at its nodes (``brdf_infer.instrument``)."""
    log_brdf = member.log_brdf_rows(data.theta_i_deg, data.theta_s_deg, physical, data.phi_s_deg)
    return through_instrument(
        log_brdf + data.log_aperture,
        data.kernel,
        lambda ti, t, p: member.log_brdf(ti, t, p, physical),
    )


def predicted_log_reflectance(
    params: Params, data: Observations, fold: bool, constants: HemisphereConstants
) -> jnp.ndarray:
    """:func:`log_reflectance` under Eq. (7) (+ Eq. 10 when ``fold``; Eq. 8 out of the plane)."""
    return log_reflectance(strumik_family(fold, constants), params._asdict(), data)


def through_instrument(point_log_reflectance, kernel: Kernel | None, log_brdf) -> jnp.ndarray:
    """The rows' ln R: Eq. (6)'s ``point_log_reflectance``, replaced on the kernel's rows by
    ln Σ w_k BRDF_k with ``log_brdf(θi, θ, φ)`` the family's BRDF [ln sr⁻¹]."""
    if kernel is None:
        return point_log_reflectance
    return jnp.where(
        kernel.applies > 0, kernel_log_reflectance(log_brdf, kernel), point_log_reflectance
    )


# latent scattering angles (``angle_method = "latent"``) can be pushed past grazing by a
# camera or rotation error; ln cos θs is held at its value here beyond it instead of NaN
GRAZING_LIMIT_DEG = 89.9


def log_cos_theta_s(theta_s_deg) -> jnp.ndarray:
    """ln cos θs of Eq. (6), finite for every θs: |θs| ≥ :data:`GRAZING_LIMIT_DEG` counts as
    that limit (ln cos 89.9° = −6.35), with a zero gradient there (a double ``where``: the
    clipped angle, not the raw one, goes into the logarithm)."""
    theta = jnp.asarray(theta_s_deg, float)
    inside = jnp.abs(theta) < GRAZING_LIMIT_DEG
    safe = jnp.where(inside, theta, GRAZING_LIMIT_DEG)
    return jnp.log(jnp.cos(safe * DEG))


def family_log_reflectance_at(
    member: ModelFamily,
    theta_i_deg,
    theta_s_deg,
    physical: Physical,
    rows: Observations | None = None,
) -> jnp.ndarray:
    """ln R(θi, θs) under ``member`` up to the constant ln Ω: ln BRDF + ln cos θs (for the
    angle slopes); with ``rows``, each row's own kind (no cos θs for BRDF rows, Eq. 8 out of the
    plane), without them in the plane at a signed θs."""
    log_cos = log_cos_theta_s(theta_s_deg)
    if rows is None:
        return member.log_brdf_signed(theta_i_deg, theta_s_deg, physical) + log_cos
    log_brdf = member.log_brdf_rows(theta_i_deg, theta_s_deg, physical, rows.phi_s_deg)
    return log_brdf + rows.cos_weight * log_cos


def log_reflectance_at(
    theta_i_deg,
    theta_s_deg,
    params: Params,
    fold: bool,
    constants: HemisphereConstants,
    rows: Observations | None = None,
) -> jnp.ndarray:
    """:func:`family_log_reflectance_at` under Eq. (7) (+ Eq. 10 when ``fold``)."""
    member = strumik_family(fold, constants)
    return family_log_reflectance_at(member, theta_i_deg, theta_s_deg, params._asdict(), rows)


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
    value's own σ_i; ``brdf_infer.fit.lsq`` adds the per-row scatter and the angle terms).
    """
    data = Observations(
        theta_i_deg=jnp.asarray(measurements.theta_i_deg),
        theta_s_deg=jnp.asarray(measurements.theta_s_deg),
        log_aperture=jnp.asarray(scene.log_conversion(measurements)),
        cos_weight=jnp.asarray(
            [
                float(scene.series[name].quantity == "raw_reflectance")
                for name in measurements.series
            ]
        ),
        phi_s_deg=None if measurements.phi_s_deg is None else jnp.asarray(measurements.phi_s_deg),
        log_reflectance=jnp.asarray(np.log(measurements.reflectance)),
        sigma=noise_layout(scene.errors, measurements).sigma_row,
        kernel=build_kernel(scene, measurements),
    )
    return ObservationModel(data, scene.model.fold, scene.model.constants)
