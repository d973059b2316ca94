"""The NumPyro model of a scene under another BRDF family (ABg, Harvey–Shack, Lambertian, …).

The same rows, instrument (Eq. 6: ln R = ln BRDF + ln cos θs + ln Ω) and generative error
model as the ``strumik2024`` posterior (:mod:`brdf_infer.posterior._model`), so that PSIS-LOO
compares the BRDF families and nothing else: only the mean of ln R changes. The family's
internal coordinates are sampled under its default priors
(:class:`brdf_infer.model.ModelFamily`); the physical parameters are deterministic sites.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpyro

from brdf_infer.error_model import angle_slopes, covariance_factors
from brdf_infer.errors import BadInputError
from brdf_infer.measurements import Measurements
from brdf_infer.model import ModelFamily
from brdf_infer.observations import log_cos_theta_s, through_instrument
from brdf_infer.posterior._likelihood import (
    LikelihoodParts,
    ModelData,
    build_model_data,
    drawn_noise_scales,
    observe,
    sample_noise_scales,
)
from brdf_infer.posterior._model import prior_distribution, row_labels
from brdf_infer.scene import Scene


@dataclass(frozen=True)
class FamilyPosteriorModel:
    """A scene's posterior under ``family``: a NumPyro model function of :class:`ModelData`.

    Attributes:
        scene: the scene (its error model; its ``[priors]`` are those of ``strumik2024``).
        family: the BRDF family.
        data: the scene's own data (the default argument of the model).
        sample_names, row_samples, row_series: as in
            :class:`brdf_infer.posterior.PosteriorModel`.
        sigma_scale: multiplies the likelihood's σ in the inference (1; a planted fault only).
    """

    scene: Scene
    family: ModelFamily
    data: ModelData
    sample_names: tuple[str, ...]
    row_samples: tuple[str, ...]
    row_series: tuple[int, ...]
    sigma_scale: float = 1.0
    whiten = False  # the family's own coordinates are sampled (no whitened reparametrisation)

    @property
    def errors(self):
        return self.scene.errors

    def sample_physical(self) -> dict:
        """Sample the internal coordinates; the physical parameters as deterministic sites."""
        internal = {
            c.site: numpyro.sample(c.site, prior_distribution(c.prior))
            for c in self.family.coordinates
        }
        physical = self.family.to_physical(internal)
        for name in self.family.parameters:
            if name not in internal:  # a coordinate that is its own parameter (g, S)
                numpyro.deterministic(name, physical[name])
        return physical

    def __call__(self, data: ModelData | None = None, mode: str = "fit") -> None:
        """The NumPyro model; ``mode`` as in :class:`brdf_infer.posterior.PosteriorModel`."""
        data = self.data if data is None else data
        scales = sample_noise_scales(self.errors, data.noise)
        physical = self.sample_physical()
        parts = self.likelihood_parts(physical, scales, data)
        observe(parts, data, mode, self.sigma_scale, spread=self.errors.model == "spread")

    def log_reflectance_at(self, theta_i_deg, theta_s_deg, physical: dict, rows) -> jnp.ndarray:
        """ln R(θi, θs) up to the constant ln Ω: ln BRDF + ln cos θs (no cos θs for BRDF rows)."""
        log_brdf = self.family.log_brdf_rows(theta_i_deg, theta_s_deg, physical, rows.phi_s_deg)
        log_cos = log_cos_theta_s(theta_s_deg)
        return log_brdf + rows.cos_weight * log_cos

    def likelihood_parts(self, physical: dict, scales, data: ModelData | None = None):
        """Mean and covariance factors of the rows' ln R for one draw (Eq. 6 in log space)."""
        data = self.data if data is None else data
        rows = data.rows
        mean = self.family.log_brdf_rows(
            rows.theta_i_deg, rows.theta_s_deg, physical, rows.phi_s_deg
        )
        mean = through_instrument(
            mean + rows.log_aperture,
            rows.kernel,
            lambda ti, t, p: self.family.log_brdf(ti, t, p, physical),
        )
        if self.errors.angles_on:
            g_rot, g_cam = angle_slopes(
                lambda ti, ts: self.log_reflectance_at(ti, ts, physical, rows),
                rows.theta_i_deg,
                rows.theta_s_deg,
                data.noise.theta_s_per_rotation,
            )
        else:
            g_rot = g_cam = jnp.zeros_like(mean)
        factor, diagonal = covariance_factors(data.noise, scales, g_rot, g_cam)
        return LikelihoodParts(mean, factor, diagonal)

    def draw_parts(self, sites: dict) -> LikelihoodParts:
        """:meth:`likelihood_parts` of every draw (leading axis) of a posterior's sites."""
        physical = {name: jnp.asarray(sites[name]) for name in self.family.parameters}
        count = next(iter(physical.values())).shape[0]
        scales = drawn_noise_scales(self.errors, self.data.noise, sites, count)
        # the data as an argument, not a constant: one compilation serves every data set
        parts = jax.jit(jax.vmap(lambda p, s, d: self.likelihood_parts(p, s, d), (0, 0, None)))
        return parts(physical, scales, self.data)


def build_family_model(
    scene: Scene, measurements: Measurements, family: ModelFamily
) -> FamilyPosteriorModel:
    """The posterior model of ``scene`` on ``measurements`` under ``family``.

    Raises:
        BadInputError: the scene asks for latent angles (only ``strumik2024`` has them).
    """
    if scene.errors.angles_on and scene.errors.angle_method == "latent":
        raise BadInputError(
            f"angle_method = 'latent' is available for strumik2024 only, not {family.name}",
            file=scene.path,
            field="errors.angle_method",
        )
    return FamilyPosteriorModel(
        scene, family, build_model_data(scene, measurements), **row_labels(measurements)
    )
