"""The error model: how a measured ln R scatters about the model's prediction.

``generative`` (the default) is a generative model in which every source of noise enters
once (README, "Error model"). For a row i of physical sample j, series c, measured at a
sample-rotation setting k,

    ln R_i = ln R_pred(θi + ε_k, θs − ε_k + η_i) + u_j + κ_c + e_i + ν_i,

with

* ``e_i ~ N(0, σ_i)``: the noise of the row's value, σ_i = σ(R_i)/(R_i √n) from the row's
  ``reflectance_err`` (or ``errors.reflectance_rel`` where the file has none), n =
  ``errors.images_per_row`` the number of images averaged into the value (Sec. 3.1: 12);
* ``ν_i ~ N(0, σ_rep)``: repeatability, what changes from one measurement setting to the next
  and so cannot show in the spread of the images of one setting; learned (half-normal prior)
  unless the scene fixes it;
* ``u_j ~ N(0, τ)``: sample-to-sample variation, shared by every row of one physical sample,
  with a learned scale τ (``errors.hierarchical``);
* ``κ_c ~ N(0, σ_cal)``: a calibration factor shared by every row of one series (one reference
  measurement per series), σ_cal = ``errors.reflectance_rel`` when
  ``errors.reflectance_rel_kind = "calibration"``;
* ``ε_k ~ N(0, σ_rot)``: the sample-rotation error of one (series, sample, θi) setting; the
  camera stays put, so θi grows by ε and θs shrinks by ε (θi + θs is fixed);
* ``η_i ~ N(0, σ_cam)``: the camera-position error of each row, which moves θs alone.

The angle errors enter through the predicted ln R (ln BRDF + ln cos θs + ln Ω), linearised:
ln R_pred(θi + ε, θs − ε + η) ≈ ln R_pred + g_rot ε + g_cam η with g_rot = ∂θi − ∂θs and
g_cam = ∂θs of ln R_pred (``angle_method = "linearised"``), or kept as latent angles
(``"latent"``, errors in variables). All effects are Gaussian in ln R, so the rows follow one
multivariate normal with covariance D + W Wᵀ: D diagonal (σ_i², σ_rep², g_cam² σ_cam²) and W
one column per sample, series and rotation setting. The samplers use it marginalised over
u, κ, ε, η (no funnels; PSIS-LOO from the leave-one-out conditionals).

``spread`` is the earlier model, kept for comparison: independent rows with
σ_i² = σ_rel² + s(θi)², s the inter-sample spread of ln R. It counts the measurement noise
twice (s is computed from values that already carry it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer.errors import BadInputError
from brdf_infer.measurements import Measurements

ERROR_MODELS = ("generative", "spread")
REFLECTANCE_REL_KINDS = ("per_row", "calibration")
ANGLE_METHODS = ("linearised", "latent")
LEARNED = "learned"


@dataclass(frozen=True)
class ErrorSettings:
    """The scene's ``[errors]`` table (see the module docstring for the model).

    Attributes:
        model: ``generative`` or ``spread`` (the earlier model, for comparison).
        reflectance_rel: relative 1σ of the measured value [-]; per row where the file has no
            σ column (``per_row``), or of one factor shared by a series (``calibration``).
        reflectance_rel_kind: ``per_row`` or ``calibration``.
        images_per_row: images averaged into each row's value; the σ column (and a per-row
            ``reflectance_rel``) is the σ of one image, so the value's σ is that over √n.
        angle_deg: 1σ of the angles [deg] (default of the next two).
        rotation_deg: 1σ of the sample rotation of one (series, sample, θi) setting [deg].
        camera_deg: 1σ of the camera position of one row [deg].
        propagate_angles: include the angle errors.
        angle_method: ``linearised`` (first order through ln R) or ``latent``.
        hierarchical: include the per-sample random effect (learned scale).
        sample_sd_prior: scale of the half-normal prior of τ [-].
        repeatability: ``"learned"`` or a fixed 1σ of the per-row repeatability [-].
        repeatability_sd_prior: scale of the half-normal prior of σ_rep [-].
    """

    model: str = "generative"
    reflectance_rel: float = 0.065
    reflectance_rel_kind: str = "per_row"
    images_per_row: int = 1
    angle_deg: float = 1.0
    rotation_deg: float = 1.0
    camera_deg: float = 1.0
    propagate_angles: bool = True
    angle_method: str = "linearised"
    hierarchical: bool = True
    sample_sd_prior: float = 0.2
    repeatability: float | str = LEARNED
    repeatability_sd_prior: float = 0.1

    @property
    def learns_repeatability(self) -> bool:
        return self.repeatability == LEARNED

    @property
    def calibration_sd(self) -> float:
        """σ_cal of the per-series factor (0 unless the kind is ``calibration``)."""
        return self.reflectance_rel if self.reflectance_rel_kind == "calibration" else 0.0

    @property
    def angles_on(self) -> bool:
        return self.model == "generative" and self.propagate_angles

    def describe(self) -> dict:
        """The settings as plain JSON values (stored with every posterior run)."""
        return {name: getattr(self, name) for name in self.__dataclass_fields__}


class NoiseLayout(NamedTuple):
    """Per-row noise structure (a pytree of arrays; data of the compiled likelihood).

    A group of one row (a sample measured once, a rotation setting with one row) adds its
    variance to that row's diagonal instead of a column of W, which keeps W narrow.

    Attributes:
        sigma_row: fixed per-row 1σ of ln R: the value's own noise σ_i (``generative``) or
            √(σ_rel² + s²) (``spread``).
        sample_members: one-hot (rows × physical samples with two or more rows).
        sample_alone: 1 where the row is its sample's only row.
        series_members: one-hot (rows × series with two or more rows).
        series_alone: 1 where the row is its series' only row.
        rotation_members: one-hot (rows × rotation settings (series, sample, θi) with two or
            more rows).
        rotation_alone: 1 where the row is its rotation setting's only row.
    """

    sigma_row: jnp.ndarray
    sample_members: jnp.ndarray
    sample_alone: jnp.ndarray
    series_members: jnp.ndarray
    series_alone: jnp.ndarray
    rotation_members: jnp.ndarray
    rotation_alone: jnp.ndarray


class NoiseScales(NamedTuple):
    """Scales of the noise sources for one draw (ln R units, angles in degrees)."""

    sample_sd: jnp.ndarray
    repeatability: jnp.ndarray
    calibration: jnp.ndarray
    rotation_deg: jnp.ndarray
    camera_deg: jnp.ndarray


def group_members(keys: list) -> tuple[np.ndarray, np.ndarray]:
    """(one-hot rows × groups of two or more rows, 1 for rows alone in their group)."""
    unique = list(dict.fromkeys(keys))
    index = np.array([unique.index(k) for k in keys], dtype=int)
    counts = np.bincount(index, minlength=len(unique))
    shared = [g for g in range(len(unique)) if counts[g] > 1]
    members = (index[:, None] == np.array(shared, dtype=int)[None, :]).astype(float)
    return members.reshape(len(keys), len(shared)), (counts[index] == 1).astype(float)


def value_sigma(settings: ErrorSettings, measurements: Measurements) -> np.ndarray:
    """σ_i of ln R from each value's own noise: σ(R)/(R √n) (see the module docstring).

    Raises:
        BadInputError: a row would have no noise at all (no σ, no ``reflectance_rel``, and
            nothing learned per row), which makes the likelihood degenerate.
    """
    n = settings.images_per_row
    if measurements.reflectance_err is not None:
        relative = measurements.reflectance_err / measurements.reflectance
    elif settings.reflectance_rel_kind == "per_row":
        relative = np.full(len(measurements), settings.reflectance_rel)
    else:
        relative = np.zeros(len(measurements))
    sigma = relative / np.sqrt(n)
    if not settings.learns_repeatability and settings.repeatability == 0 and np.any(sigma <= 0):
        row = int(np.argmax(sigma <= 0)) + 1
        raise BadInputError(
            "the error model gives this row no noise: give it a reflectance_err > 0, set "
            "errors.reflectance_rel > 0 (per_row), or let errors.repeatability be learned",
            file=measurements.path,
            row=row,
            field="reflectance_err",
        )
    return sigma


def inter_sample_spread(measurements: Measurements) -> np.ndarray:
    """s(θi) of every row (``spread`` model): std of ln R over samples, interpolated in θi.

    The std (ddof = 1) is taken over the samples measured at one geometry (series, θi, θs),
    pooled per θi, and interpolated in θi (constant beyond the ends). Zeros when no geometry
    was measured on two or more samples.
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


def spread_sigma(reflectance_rel: float, measurements: Measurements) -> np.ndarray:
    """σ_i of the ``spread`` model: √(σ_rel² + s(θi)²).

    Raises:
        BadInputError: some σ_i is zero (no relative uncertainty and no spread).
    """
    sigma = np.sqrt(reflectance_rel**2 + inter_sample_spread(measurements) ** 2)
    if np.any(sigma <= 0):
        raise BadInputError(
            "the error model gives zero uncertainty: set errors.reflectance_rel > 0",
            file=measurements.path,
            field="errors.reflectance_rel",
        )
    return sigma


def noise_layout(settings: ErrorSettings, measurements: Measurements) -> NoiseLayout:
    """The per-row noise structure of ``measurements`` under ``settings``."""
    if settings.model == "spread":
        sigma = spread_sigma(settings.reflectance_rel, measurements)
    else:
        sigma = value_sigma(settings, measurements)
    rotation_keys = list(
        zip(measurements.series, measurements.sample, measurements.theta_i_deg, strict=True)
    )
    samples = group_members(list(measurements.sample))
    series = group_members(list(measurements.series))
    rotations = group_members(rotation_keys)
    return NoiseLayout(
        jnp.asarray(sigma),
        *(jnp.asarray(array) for array in (*samples, *series, *rotations)),
    )


def angle_slopes(log_reflectance_at, theta_i_deg, theta_s_deg) -> tuple[jnp.ndarray, jnp.ndarray]:
    """(g_rot, g_cam) per row [1/deg]: the first-order response of ln R to the angle errors.

    Two forward-mode directional derivatives of the elementwise ln R_pred over all rows.

    Args:
        log_reflectance_at: ln R_pred(θi, θs), elementwise over arrays of angles (the
            aperture's ln Ω may be left out, it does not depend on the angles).
        theta_i_deg, theta_s_deg: the rows' nominal angles [deg].

    Returns:
        g_rot = ∂ln R/∂θi − ∂ln R/∂θs (sample rotation: θi + ε, θs − ε) and
        g_cam = ∂ln R/∂θs (camera position: θs + η).
    """
    ones = jnp.ones_like(theta_i_deg)
    angles = (theta_i_deg, theta_s_deg)
    g_rot = jax.jvp(log_reflectance_at, angles, (ones, -ones))[1]
    g_cam = jax.jvp(log_reflectance_at, angles, (jnp.zeros_like(ones), ones))[1]
    return g_rot, g_cam


def covariance_factors(
    layout: NoiseLayout,
    scales: NoiseScales,
    g_rot: jnp.ndarray,
    g_cam: jnp.ndarray,
) -> tuple[jnp.ndarray, jnp.ndarray]:
    """(W, D) with Cov(ln R) = D + W Wᵀ (module docstring).

    D = σ_i² + σ_rep² + (g_cam σ_cam)² (+ the variance of groups of one row);
    W = [τ·samples, σ_cal·series, σ_rot·g_rot·settings]. Pass zero slopes for the latent-angle
    model (the angles are then sampled, not marginalised).
    """
    rotation = scales.rotation_deg * g_rot
    diagonal = (
        layout.sigma_row**2
        + scales.repeatability**2
        + (g_cam * scales.camera_deg) ** 2
        + layout.sample_alone * scales.sample_sd**2
        + layout.series_alone * scales.calibration**2
        + layout.rotation_alone * rotation**2
    )
    factor = jnp.concatenate(
        [
            scales.sample_sd * layout.sample_members,
            scales.calibration * layout.series_members,
            rotation[:, None] * layout.rotation_members,
        ],
        axis=1,
    )
    return factor, diagonal
