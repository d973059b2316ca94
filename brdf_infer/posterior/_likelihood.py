"""The likelihood of the rows' ln R: the model's data (:class:`ModelData`), the mean and
covariance D + W Wᵀ of one draw (:class:`LikelihoodParts`), the ``obs`` site under them
(:func:`observe`, :class:`LowRankNormal`) and the error model's noise scales, sampled or drawn
(:mod:`brdf_infer.model.error_model`)."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpyro
import numpyro.distributions as dist

from brdf_infer._internal.lowrank import low_rank_normal_log_density
from brdf_infer.model.error_model import ErrorSettings, NoiseLayout, NoiseScales, noise_layout
from brdf_infer.predict.observations import Observations, build_observation_model
from brdf_infer.scene import Scene
from brdf_infer.tables.measurements import Measurements


class ModelData(NamedTuple):
    """Everything data-dependent the model needs (a pytree: an argument of compiled code).

    Attributes:
        rows: geometry and measured ln R of each row.
        noise: the rows' noise structure.
        mask: (rows,) 1 for a measured row, 0 for a padding row (a batch of scenes of unequal
            size pads them to one shape); padding rows leave the likelihood and the
            whitening regression exactly.
    """

    rows: Observations
    noise: NoiseLayout
    mask: jnp.ndarray


class LikelihoodParts(NamedTuple):
    """Mean, low-rank factor W and diagonal D of the rows' ln R (Cov = D + W Wᵀ)."""

    mean: jnp.ndarray
    factor: jnp.ndarray
    diagonal: jnp.ndarray


def observe(
    parts: LikelihoodParts, data: ModelData, mode: str, sigma_scale: float, *, spread: bool
) -> None:
    """The ``obs`` site: the rows' ln R under mean and covariance ``parts`` (observed in
    ``fit`` mode, drawn otherwise); σ scaled by ``sigma_scale`` except when simulating.
    Padding rows (``data.mask`` 0) add nothing to the log density."""
    observed = data.rows.log_reflectance if mode == "fit" else None
    if mode != "simulate" and sigma_scale != 1.0:
        parts = LikelihoodParts(
            parts.mean, parts.factor * sigma_scale, parts.diagonal * sigma_scale**2
        )
    measured = data.mask > 0
    if spread:
        rows = numpyro.plate("rows", data.rows.log_reflectance.shape[0])
        with rows, numpyro.handlers.mask(mask=measured):
            numpyro.sample("obs", dist.Normal(parts.mean, parts.diagonal**0.5), obs=observed)
    else:
        factor, diagonal = mask_rows(measured, parts.factor, parts.diagonal)
        mean = jnp.where(measured, parts.mean, data.rows.log_reflectance)
        numpyro.sample(
            "obs",
            LowRankNormal(mean, factor, diagonal, measured, disjoint_columns(data)),
            obs=observed,
        )


def disjoint_columns(data: ModelData) -> int:
    """The leading columns of the rows' covariance factor W whose rows do not overlap: one per
    physical sample (each row belongs to one sample), so the capacitance's leading block is
    diagonal (:class:`brdf_infer._internal.lowrank.BlockCholesky`)."""
    return data.noise.sample_members.shape[-1]


def mask_rows(keep: jnp.ndarray, factor: jnp.ndarray, diagonal: jnp.ndarray):
    """(W, D) with the rows outside ``keep`` made independent unit-variance rows (W row 0,
    D = 1): with a zero residual there they add nothing but the 2π constant."""
    return jnp.where(keep[:, None], factor, 0.0), jnp.where(keep, diagonal, 1.0)


class LowRankNormal(dist.Distribution):
    """N(mean, D + W Wᵀ) over the rows, its log density in fused XLA ops (``_internal.lowrank``).

    Rows outside ``keep`` (masked: W row 0, D = 1, mean = the observed value) are left out of
    the 2π normalisation, so they leave the log density exactly.
    """

    arg_constraints = {}  # noqa: RUF012 (NumPyro's class attribute)
    support = dist.constraints.real_vector

    def __init__(self, mean, factor, diagonal, keep=None, disjoint: int = 0):
        self.loc, self.factor, self.diagonal = mean, factor, diagonal
        self.disjoint = disjoint
        self.keep = jnp.ones(mean.shape[-1], bool) if keep is None else keep
        super().__init__(batch_shape=(), event_shape=mean.shape[-1:])

    def sample(self, key, sample_shape=()):
        rank_key, row_key = jax.random.split(key)
        shared = jax.random.normal(rank_key, (*sample_shape, self.factor.shape[-1]))
        own = jax.random.normal(row_key, (*sample_shape, self.loc.shape[-1]))
        return self.loc + shared @ self.factor.T + own * jnp.sqrt(self.diagonal)

    @property
    def mean(self):
        return self.loc

    @property
    def variance(self):
        return self.diagonal + jnp.sum(self.factor**2, axis=-1)

    def log_prob(self, value):
        count = jnp.sum(self.keep)
        return low_rank_normal_log_density(
            value, self.loc, self.factor, self.diagonal, count, self.disjoint
        )


def noise_prior(errors: ErrorSettings, site: str) -> dist.Distribution:
    """The prior of a learned noise scale: ``repeatability`` half-normal; τ (``sample_sd``)
    half-normal, or another run's τ posterior (``errors.sample_sd_from``): the Gaussian kernel
    density of its ln τ (``errors.sample_sd_log_kde``) carried to τ."""
    if site == "repeatability":
        return dist.HalfNormal(errors.repeatability_sd_prior)
    if errors.sample_sd_log_kde is not None:
        centres, widths = (jnp.asarray(v, float) for v in errors.sample_sd_log_kde)
        kernels = dist.MixtureSameFamily(
            dist.Categorical(probs=jnp.full(centres.shape, 1.0 / centres.size)),
            dist.Normal(centres, widths),
        )
        return dist.TransformedDistribution(kernels, dist.transforms.ExpTransform())
    return dist.HalfNormal(errors.sample_sd_prior)


def sample_noise_scales(errors: ErrorSettings, noise: NoiseLayout) -> NoiseScales:
    """The noise scales of the error model: NumPyro sites where they are learned (stated ones
    as stated); the calibration's from the data (``noise``)."""
    generative = errors.model == "generative"
    if errors.learns_sample_sd:
        sample_sd = numpyro.sample("sample_sd", noise_prior(errors, "sample_sd"))
    else:
        sample_sd = jnp.asarray(errors.stated_sample_sd)
    if generative and errors.learns_repeatability:
        repeatability = numpyro.sample("repeatability", noise_prior(errors, "repeatability"))
    else:
        repeatability = jnp.asarray(0.0 if not generative else float(errors.repeatability))
    return NoiseScales(
        sample_sd=sample_sd,
        repeatability=repeatability,
        calibration=jnp.asarray(noise.calibration_sd),
        rotation_deg=jnp.asarray(noise.rotation_deg),
        camera_deg=jnp.asarray(noise.camera_deg),
    )


def drawn_noise_scales(
    errors: ErrorSettings, noise: NoiseLayout, sites: dict, count: int
) -> NoiseScales:
    """The noise scales of ``count`` posterior draws (learned ones from ``sites``, the
    calibration's from the data, ``noise``)."""
    generative = errors.model == "generative"
    return NoiseScales(
        sample_sd=jnp.asarray(sites.get("sample_sd", jnp.full(count, errors.stated_sample_sd))),
        repeatability=jnp.asarray(
            sites["repeatability"]
            if "repeatability" in sites
            else jnp.full(count, float(errors.repeatability) if generative else 0.0)
        ),
        calibration=_per_draw(noise.calibration_sd, count),
        rotation_deg=_per_draw(noise.rotation_deg, count),
        camera_deg=_per_draw(noise.camera_deg, count),
    )


def _per_draw(per_row: jnp.ndarray, count: int) -> jnp.ndarray:
    """A per-row scale of the layout repeated for ``count`` draws: (count, rows)."""
    per_row = jnp.asarray(per_row)
    return jnp.broadcast_to(per_row, (count, *per_row.shape))


def build_model_data(scene: Scene, measurements: Measurements) -> ModelData:
    """The :class:`ModelData` of ``measurements`` under ``scene``."""
    rows = build_observation_model(scene, measurements).data
    return ModelData(
        rows=rows,
        noise=noise_layout(scene.errors, measurements),
        mask=jnp.ones(len(measurements)),
    )
