"""The error model: how a measured ln R scatters about the model's prediction.

``generative`` (the default) is a generative model in which every source of noise enters
once (docs/error-model.md). For a row i of physical sample j, series c, measured at a
sample-rotation setting k,

    ln R_i = ln R_pred(θi + ε_k, θs + s ε_k + η_i) + u_j + κ_g + e_i + ν_i,

with

* ``e_i ~ N(0, σ_i)``: the noise of the row's value, σ_i = σ(R_i)/(R_i √n_c) from the row's
  ``reflectance_err`` (or ``errors.reflectance_rel`` where the file has none), n_c =
  ``errors.images_per_row`` of the row's series, the number of images averaged into the value
  (Sec. 3.1: 12 for series I);
* ``ν_i ~ N(0, σ_rep)``: repeatability, what changes from one measurement setting to the next
  and so cannot show in the spread of the images of one setting; learned (half-normal prior)
  unless the scene fixes it;
* ``u_j ~ N(0, τ)``: sample-to-sample variation, shared by every row of one physical sample,
  with a learned scale τ (``errors.hierarchical``);
* ``κ_g ~ N(0, σ_cal)``: the calibration factor of one reference measurement, shared by every
  row normalised by it (Eq. 2 divides by the reference): one per series
  (``errors.calibration = "per_series"``), one per (series, sample) (``"per_sample"``) or none
  (``"none"``); σ_cal = ``errors.calibration_rel``;
* ``ε_k ~ N(0, σ_rot)``: the sample-rotation error of one (series, sample, θi) setting;
* ``η_i ~ N(0, σ_cam)``: the camera-position error of each row, which moves θs alone.

The rotation coupling s (``errors.rotation_coupling``) is what a rotation error does to θs.
In the plane of incidence, measure lab angles from the direction back to the source (the
beam is fixed): the sample normal lies at θi, the camera at θi + θs (θs from the normal, on
the far side; θs = θi + δ, Eq. 1), the specular beam at 2θi. Turning the sample by ε turns
its normal to θi + ε and the specular beam to 2(θi + ε).

* ``"camera_follows"`` (s = +1): the camera is set on the specular beam of the sample as it
  actually stands and moved by δ from there — Sec. 2: "The camera's position was manually
  adjusted to receive either the specularly reflected beam for each incidence angle ... or the
  reflected signal for off-specular case", Sec. 3.2: δ "from the specular reflection
  position". The camera sits at 2(θi + ε) + δ, so θs → 2(θi + ε) + δ − (θi + ε) = θs + ε: a
  specular row stays specular, at θi + ε.
* ``"camera_fixed"`` (s = −1): the camera stays where the nominal geometry puts it, at
  θi + θs, so θs → θi + θs − (θi + ε) = θs − ε (θi + θs fixed): a specular row leaves the
  specular ridge by 2ε.

The angle errors enter through the predicted ln R (ln BRDF + ln cos θs + ln Ω), linearised:
ln R_pred(θi + ε, θs + s ε + η) ≈ ln R_pred + g_rot ε + g_cam η with g_rot = ∂θi + s ∂θs and
g_cam = ∂θs of ln R_pred (``angle_method = "linearised"``), or kept as latent angles
(``"latent"``, errors in variables). All effects are Gaussian in ln R, so the rows follow one
multivariate normal with covariance D + W Wᵀ: D diagonal (σ_i², σ_rep², g_cam² σ_cam²) and W
one column per sample, calibration group and rotation setting. The samplers use it
marginalised over u, κ, ε, η (no funnels; PSIS-LOO from the leave-one-out conditionals).

Where each option enters, once: ``images_per_row`` and ``reflectance_rel`` in σ_i,
``calibration`` in the calibration columns of W (which rows share a factor),
``calibration_rel`` in their scale σ_cal, ``rotation_coupling`` in s of g_rot,
``rotation_deg`` and ``camera_deg`` (``angle_deg`` their default) in the scales σ_rot, σ_cam of
the angle terms (0 where the angle errors are off). All of them are data of the compiled
likelihood (:class:`NoiseLayout`), not constants of the model: one
compiled program samples, and simulates from, every combination of them, and data simulated
under one layout can be fitted under another (misspecification studies).

``spread`` is the earlier model, kept for comparison: independent rows with
σ_i² = σ_rel² + s(θi)², s the inter-sample spread of ln R, σ_rel = ``reflectance_rel``. It
counts the measurement noise twice (s is computed from values that already carry it).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer.errors import BadInputError
from brdf_infer.tables.measurements import CAMPAIGN_SEPARATOR, Measurements

ERROR_MODELS = ("generative", "spread")
CALIBRATIONS = ("per_series", "per_sample", "none")
ROTATION_COUPLINGS = ("camera_follows", "camera_fixed")
# s = ∂θs/∂ε, the change of θs per unit sample-rotation error (module docstring)
THETA_S_PER_ROTATION = {"camera_follows": 1.0, "camera_fixed": -1.0}
ANGLE_METHODS = ("linearised", "latent")
# settings a scene's [errors] does not hold: loading derives them from its keys
DERIVED = ("sample_sd_log_kde", "campaign_errors")
LEARNED = "learned"
# the options that are data of the compiled likelihood (NoiseLayout), not model structure
DATA_OPTIONS = (
    "reflectance_rel",
    "calibration",
    "calibration_rel",
    "rotation_coupling",
    "images_per_row",
    "angle_deg",
    "rotation_deg",
    "camera_deg",
)


@dataclass(frozen=True)
class ErrorSettings:
    """The scene's ``[errors]`` table (see the module docstring for the model).

    The defaults are argued from the article in docs/error-model.md: the 6.5 % of
    Sec. 5.3 as a calibration per series, the camera following the specular beam (Sec. 2),
    one image per row where the number averaged is not stated.

    Attributes:
        model: ``generative`` or ``spread`` (the earlier model, for comparison).
        reflectance_rel: relative 1σ of one image of a row without ``reflectance_err`` [-]
            (and the σ_rel of the ``spread`` model).
        calibration: which rows share one calibration factor: ``per_series``, ``per_sample``
            (one per series and physical sample) or ``none``.
        calibration_rel: relative 1σ of a calibration factor [-].
        rotation_coupling: ``camera_follows`` (θs + ε under a rotation error ε) or
            ``camera_fixed`` (θs − ε).
        images_per_row: images averaged into each row's value, one number for every series
            or a mapping series name → number (series not named: 1); the σ column (and
            ``reflectance_rel``) is the σ of one image, so the value's σ is that over √n.
        angle_deg: 1σ of the angles [deg] (default of the next two).
        rotation_deg: 1σ of the sample rotation of one (series, sample, θi) setting [deg].
        camera_deg: 1σ of the camera position of one row [deg].
        propagate_angles: include the angle errors.
        angle_method: ``linearised`` (first order through ln R) or ``latent``.
        hierarchical: include the per-sample random effect.
        sample_sd: ``"learned"`` (τ sampled under its prior) or a stated τ [ln R], which
            needs ``sample_sd_source``.
        sample_sd_source: where a stated τ comes from, in words (kept with the run).
        sample_sd_prior: scale of the half-normal prior of τ [-] (the default prior).
        sample_sd_from: a posterior run of the same coating whose τ posterior is this
            scene's prior of τ (the folder as the scene names it); its draws are summarised
            as ``sample_sd_log_kde``.
        sample_sd_log_kde: (centres, widths) of the kernels of a Gaussian kernel density of
            ln τ over that run's draws: τ's prior is that density carried to τ (None: the
            half-normal of ``sample_sd_prior``).
        repeatability: ``"learned"`` or a fixed 1σ of the per-row repeatability [-].
        repeatability_sd_prior: scale of the half-normal prior of σ_rep [-].
        expected_repeatability: the per-row scatter beyond each row's own σ and the angle
            terms that the instrument is known to reach, sample and calibration scatter
            included: what judges a least-squares fit's learned σ_rep
            (:mod:`brdf_infer.fit.quality`) [ln R]; a scene without the key gets its
            ``reflectance_rel`` (0.065 by default).
        campaign_errors: a pooled scene's campaigns (``[campaigns.NAME]``), each with the
            :data:`DATA_OPTIONS` its own ``[campaigns.NAME.errors]`` sets over these (empty:
            one measurement file, no campaigns); a campaign's rows are those whose series
            is named ``NAME/…`` (:func:`row_campaigns`).
    """

    model: str = "generative"
    reflectance_rel: float = 0.065
    calibration: str = "per_series"
    calibration_rel: float = 0.065
    rotation_coupling: str = "camera_follows"
    images_per_row: int | dict[str, int] = 1
    angle_deg: float = 1.0
    rotation_deg: float = 1.0
    camera_deg: float = 1.0
    propagate_angles: bool = True
    angle_method: str = "linearised"
    hierarchical: bool = True
    sample_sd: float | str = LEARNED
    sample_sd_source: str = ""
    sample_sd_prior: float = 0.2
    sample_sd_from: str = ""
    sample_sd_log_kde: tuple[tuple[float, ...], tuple[float, ...]] | None = None
    repeatability: float | str = LEARNED
    repeatability_sd_prior: float = 0.1
    expected_repeatability: float = 0.065
    campaign_errors: dict[str, dict] = field(default_factory=dict)

    def of_campaign(self, name: str) -> ErrorSettings:
        """The settings of campaign ``name``'s rows: these with its own data options over
        them (its own per-series ``images_per_row`` names its series without the prefix)."""
        own = dict(self.campaign_errors[name])
        images = own.get("images_per_row")
        if isinstance(images, dict):
            own["images_per_row"] = {
                f"{name}{CAMPAIGN_SEPARATOR}{series}": count for series, count in images.items()
            }
        return replace(self, **own, campaign_errors={})

    @property
    def learns_repeatability(self) -> bool:
        return self.repeatability == LEARNED

    @property
    def sample_effects(self) -> bool:
        """The rows carry a per-sample effect u_j (``generative`` with ``hierarchical``)."""
        return self.model == "generative" and self.hierarchical

    @property
    def learns_sample_sd(self) -> bool:
        """τ is a sampled site (a sample effect, τ not stated)."""
        return self.sample_effects and self.sample_sd == LEARNED

    @property
    def stated_sample_sd(self) -> float:
        """τ where it is not sampled: the stated value, or 0 without sample effects."""
        return float(self.sample_sd) if self.sample_effects and not self.learns_sample_sd else 0.0

    def sample_sd_prior_words(self) -> str:
        """τ's prior in words (the learned record's "set by its prior (…)")."""
        if self.sample_sd_log_kde is None:
            return f"half-normal, scale {self.sample_sd_prior:g}"
        low, median, high = np.exp(np.quantile(self.sample_sd_log_kde[0], [0.025, 0.5, 0.975]))
        return (
            f"run {self.sample_sd_from}'s τ posterior: median {median:.3g}, "
            f"95 % {low:.3g}–{high:.3g}"
        )

    @property
    def calibration_sd(self) -> float:
        """σ_cal of the calibration factors (0 without a calibration or under ``spread``)."""
        if self.model != "generative" or self.calibration == "none":
            return 0.0
        return self.calibration_rel

    @property
    def angles_on(self) -> bool:
        return self.model == "generative" and self.propagate_angles

    def images_of(self, series: str) -> int:
        """Images averaged into a row of ``series``."""
        if isinstance(self.images_per_row, dict):
            return self.images_per_row.get(series, 1)
        return self.images_per_row

    def describe(self) -> dict:
        """The settings as plain JSON values (stored with every posterior run)."""
        return {
            name: dict(value) if isinstance(value, dict) else value
            for name, value in ((n, getattr(self, n)) for n in self.__dataclass_fields__)
        }

    def as_table(self) -> dict:
        """:meth:`describe` as a scene's ``[errors]`` table: without what loading derives from
        it (:data:`DERIVED`), so that it parses back to these settings."""
        return {k: v for k, v in self.describe().items() if k not in DERIVED}

    def structure(self) -> dict:
        """:meth:`describe` without :data:`DATA_OPTIONS` and ``expected_repeatability`` (which
        only judges least-squares fits): what the compiled model depends on. Settings with the
        same structure share one compiled program; their data differ."""
        return {
            k: v
            for k, v in self.describe().items()
            if k not in (*DATA_OPTIONS, "expected_repeatability", "campaign_errors")
        }


class NoiseLayout(NamedTuple):
    """Per-row noise structure (a pytree of arrays; data of the compiled likelihood).

    A group of one row (a sample measured once, a calibration or rotation setting with one
    row) adds its variance to that row's diagonal instead of a column of W, which keeps W
    narrow.

    Attributes:
        sigma_row: fixed per-row 1σ of ln R: the value's own noise σ_i (``generative``) or
            √(σ_rel² + s²) (``spread``).
        sample_members: one-hot (rows × physical samples with two or more rows).
        sample_alone: 1 where the row is its sample's only row.
        calibration_members: one-hot (rows × calibration groups with two or more rows): the
            series, the (series, sample) pairs, or none (``errors.calibration``).
        calibration_alone: 1 where the row is its calibration group's only row.
        calibration_sd: σ_cal of the row's calibration factor [ln R] (0: none).
        rotation_members: one-hot (rows × rotation settings (series, sample, θi) with two or
            more rows).
        rotation_alone: 1 where the row is its rotation setting's only row.
        theta_s_per_rotation: s = ∂θs/∂ε of each row: +1 when the camera follows the specular
            beam, −1 when it stays put (``errors.rotation_coupling``).
        rotation_deg: σ_rot of the row's sample rotation [deg] (0: the angle errors off).
        camera_deg: σ_cam of the row's camera position [deg] (0: the angle errors off).
    """

    sigma_row: jnp.ndarray
    sample_members: jnp.ndarray
    sample_alone: jnp.ndarray
    calibration_members: jnp.ndarray
    calibration_alone: jnp.ndarray
    calibration_sd: jnp.ndarray
    rotation_members: jnp.ndarray
    rotation_alone: jnp.ndarray
    theta_s_per_rotation: jnp.ndarray
    rotation_deg: jnp.ndarray
    camera_deg: jnp.ndarray


class NoiseScales(NamedTuple):
    """Scales of the noise sources for one draw (ln R units, angles in degrees): τ and σ_rep
    one each; σ_cal, σ_rot and σ_cam per row (:class:`NoiseLayout`) or one for all."""

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
    """σ_i of ln R from each value's own noise: σ(R)/(R √n) with n the images of the row's
    series (see the module docstring).

    Raises:
        BadInputError: a row would have no noise at all (no σ, no ``reflectance_rel``, and
            nothing learned per row), which makes the likelihood degenerate.
    """
    images = np.array([settings.images_of(str(s)) for s in measurements.series], dtype=float)
    if measurements.reflectance_err is not None:
        relative = measurements.reflectance_err / measurements.reflectance
    else:
        relative = np.full(len(measurements), settings.reflectance_rel)
    sigma = relative / np.sqrt(images)
    if not settings.learns_repeatability and settings.repeatability == 0 and np.any(sigma <= 0):
        row = int(np.argmax(sigma <= 0)) + 1
        raise BadInputError(
            "the error model gives this row no noise: give it a reflectance_err > 0, set "
            "errors.reflectance_rel > 0, or let errors.repeatability be learned",
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


def calibration_groups(settings: ErrorSettings, measurements: Measurements) -> list | None:
    """The calibration group of each row: its series, or its (series, sample); None without a
    calibration."""
    if settings.calibration == "per_series":
        return list(measurements.series)
    if settings.calibration == "per_sample":
        return list(zip(measurements.series, measurements.sample, strict=True))
    return None


def theta_s_per_rotation(settings: ErrorSettings, rows: int) -> np.ndarray:
    """s = ∂θs/∂ε of ``rows`` rows under the scene's rotation coupling (module docstring)."""
    return np.full(rows, THETA_S_PER_ROTATION[settings.rotation_coupling])


def row_campaigns(measurements: Measurements) -> np.ndarray:
    """The campaign of each row of a pooled scene: its series' name before
    :data:`CAMPAIGN_SEPARATOR`."""
    return np.array([str(s).split(CAMPAIGN_SEPARATOR, 1)[0] for s in measurements.series])


def campaign_rows(
    settings: ErrorSettings, measurements: Measurements
) -> list[tuple[ErrorSettings, np.ndarray]]:
    """(settings, row mask) of each campaign of a pooled scene; one pair of the whole table
    under ``settings`` for a scene of one measurement file."""
    if not settings.campaign_errors:
        return [(settings, np.ones(len(measurements), bool))]
    campaigns = row_campaigns(measurements)
    return [(settings.of_campaign(name), campaigns == name) for name in settings.campaign_errors]


def _row_noise(settings: ErrorSettings, measurements: Measurements) -> dict[str, np.ndarray]:
    """The per-row noise values of one campaign's rows (or a whole table's): σ_i, σ_cal, s,
    σ_rot, σ_cam."""
    rows = len(measurements)
    if settings.model == "spread":
        sigma = spread_sigma(settings.reflectance_rel, measurements)
    else:
        sigma = value_sigma(settings, measurements)
    angles = 1.0 if settings.angles_on else 0.0
    return {
        "sigma": sigma,
        "calibration_sd": np.full(rows, settings.calibration_sd),
        "coupling": theta_s_per_rotation(settings, rows),
        "rotation_deg": np.full(rows, settings.rotation_deg * angles),
        "camera_deg": np.full(rows, settings.camera_deg * angles),
    }


def row_calibration_groups(settings: ErrorSettings, measurements: Measurements) -> list:
    """The calibration group key of every row, each campaign's under its own
    ``calibration`` (:func:`calibration_groups`); a row without a calibration is a group of
    its own."""
    groups: list = [("alone", i) for i in range(len(measurements))]
    for own, mask in campaign_rows(settings, measurements):
        keys = calibration_groups(own, measurements.subset(mask))
        if keys is not None:
            for index, key in zip(np.flatnonzero(mask), keys, strict=True):
                groups[index] = key
    return groups


def calibration_group_names(settings: ErrorSettings, measurements: Measurements) -> list[str]:
    """The calibration groups of two or more rows (W's calibration columns, in their order)
    by name: the series, or "series, sample"."""
    counts = Counter(row_calibration_groups(settings, measurements))  # in first-seen order
    return [
        str(key) if isinstance(key, str) else ", ".join(map(str, key))
        for key, count in counts.items()
        if count > 1
    ]


def noise_layout(settings: ErrorSettings, measurements: Measurements) -> NoiseLayout:
    """The per-row noise structure of ``measurements`` under ``settings`` (each campaign's
    rows of a pooled scene under its own settings, :func:`campaign_rows`)."""
    rows = len(measurements)
    values: dict[str, np.ndarray] = {}
    for own, mask in campaign_rows(settings, measurements):
        part = _row_noise(own, measurements.subset(mask))
        for name, value in part.items():
            values.setdefault(name, np.zeros(rows))[mask] = value
    groups = row_calibration_groups(settings, measurements)
    rotation_keys = list(
        zip(measurements.series, measurements.sample, measurements.theta_i_deg, strict=True)
    )
    samples = group_members(list(measurements.sample))
    calibration = group_members(groups)
    has_calibration = values["calibration_sd"] > 0  # rows without one: alone, variance 0
    rotations = group_members(rotation_keys)
    return NoiseLayout(
        sigma_row=jnp.asarray(values["sigma"]),
        sample_members=jnp.asarray(samples[0]),
        sample_alone=jnp.asarray(samples[1]),
        calibration_members=jnp.asarray(calibration[0]),
        calibration_alone=jnp.asarray(calibration[1] * has_calibration),
        calibration_sd=jnp.asarray(values["calibration_sd"]),
        rotation_members=jnp.asarray(rotations[0]),
        rotation_alone=jnp.asarray(rotations[1]),
        theta_s_per_rotation=jnp.asarray(values["coupling"]),
        rotation_deg=jnp.asarray(values["rotation_deg"]),
        camera_deg=jnp.asarray(values["camera_deg"]),
    )


def angle_slopes(
    log_reflectance_at, theta_i_deg, theta_s_deg, theta_s_per_rotation
) -> tuple[jnp.ndarray, jnp.ndarray]:
    """(g_rot, g_cam) per row [1/deg]: the first-order response of ln R to the angle errors.

    Two forward-mode directional derivatives of the elementwise ln R_pred over all rows.

    Args:
        log_reflectance_at: ln R_pred(θi, θs), elementwise over arrays of angles (the
            aperture's ln Ω may be left out, it does not depend on the angles).
        theta_i_deg, theta_s_deg: the rows' nominal angles [deg].
        theta_s_per_rotation: s = ∂θs/∂ε per row (or one for all): +1 camera follows the
            specular beam, −1 camera fixed (:attr:`NoiseLayout.theta_s_per_rotation`).

    Returns:
        g_rot = ∂ln R/∂θi + s ∂ln R/∂θs (sample rotation: θi + ε, θs + s ε) and
        g_cam = ∂ln R/∂θs (camera position: θs + η).
    """
    ones = jnp.ones_like(theta_i_deg)
    angles = (theta_i_deg, theta_s_deg)
    coupling = theta_s_per_rotation * ones
    g_rot = jax.jvp(log_reflectance_at, angles, (ones, coupling))[1]
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
    W = [τ·samples, σ_cal·calibration groups, σ_rot·g_rot·settings]. Pass zero slopes for the
    latent-angle model (the angles are then sampled, not marginalised).
    """
    rotation = scales.rotation_deg * g_rot
    diagonal = (
        layout.sigma_row**2
        + scales.repeatability**2
        + (g_cam * scales.camera_deg) ** 2
        + layout.sample_alone * scales.sample_sd**2
        + layout.calibration_alone * scales.calibration**2
        + layout.rotation_alone * rotation**2
    )
    factor = jnp.concatenate(
        [
            scales.sample_sd * layout.sample_members,
            jnp.expand_dims(scales.calibration, -1) * layout.calibration_members,
            rotation[:, None] * layout.rotation_members,
        ],
        axis=1,
    )
    return factor, diagonal
