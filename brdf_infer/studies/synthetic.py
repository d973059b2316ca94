"""Synthetic measurements from known parameters at a scene's measurement geometry."""

from __future__ import annotations

import copy
from dataclasses import replace
from pathlib import Path

import numpy as np

from brdf_infer._internal.precision import ensure_float64
from brdf_infer.model.params import Params
from brdf_infer.predict.observations import build_observation_model, predicted_log_reflectance
from brdf_infer.scene import Scene
from brdf_infer.tables.measurements import Measurements


def synthetic_measurements(
    scene: Scene,
    template: Measurements,
    params: Params,
    *,
    noise_rel: float = 0.0,
    seed: int = 0,
) -> Measurements:
    """Rows of ``template`` with reflectance predicted by ``params`` along the one forward
    path of the fits and the posterior (:func:`brdf_infer.predict.observations.log_reflectance`:
    Eqs. 6, 7, 10; Eq. 8 out of the plane; the scene's instrument kernel).

    Args:
        scene: apertures, instrument and model components (folding).
        template: the geometry (series, sample, θi, θs) to reproduce.
        params: the generating parameters, paper units.
        noise_rel: 1σ of multiplicative log-normal noise, e.g. 0.065 [-].
        seed: noise seed.

    Returns:
        A table like ``template`` with new ``reflectance`` and ``reflectance_err = noise_rel·R``.
    """
    rows = build_observation_model(scene, template).data
    log_clean = predicted_log_reflectance(params, rows, scene.model.fold, scene.model.constants)
    clean = np.exp(np.asarray(log_clean))
    noise = np.random.default_rng(seed).normal(0.0, noise_rel, clean.shape) if noise_rel else 0.0
    reflectance = clean * np.exp(noise)
    return replace(template, reflectance=reflectance, reflectance_err=noise_rel * reflectance)


def simulate_measurements(
    scene: Scene,
    template: Measurements,
    params: Params,
    *,
    sample_sd: float = 0.03,
    repeatability: float = 0.07,
    seed: int = 0,
) -> Measurements:
    """Rows of ``template`` drawn from the scene's own generative error model at ``params``.

    Every noise source of the scene's error model is drawn (value noise from the rows'
    σ, repeatability, sample and calibration effects, angle errors); the learned scales are
    set to ``sample_sd`` and ``repeatability`` where the scene learns them.

    Returns:
        A table like ``template`` (same σ column) with simulated ``reflectance``.
    """
    ensure_float64()
    import jax
    from numpyro import handlers
    from numpyro.infer import Predictive

    from brdf_infer.model.coordinates import INTERNAL_NAMES, to_internal
    from brdf_infer.posterior import build_posterior_model

    model = build_posterior_model(scene, template)
    internal = dict(zip(INTERNAL_NAMES, np.asarray(to_internal(params)), strict=True))
    truth = {name: internal[name] for name in ("log_brdf0", "b1", "b2", "b3", "alpha", "t_s0")}
    truth.update(sample_sd=sample_sd, repeatability=repeatability)
    conditioned = handlers.condition(model, data=truth)
    draw = Predictive(conditioned, num_samples=1)(jax.random.PRNGKey(seed), mode="simulate")
    return replace(template, reflectance=np.exp(np.asarray(draw["obs"][0])))


# Measurement geometries unlike the bundled scene's, for checking that sampling stays clean on
# other data: (sample, θi, θs) per row [deg], one series.
GEOMETRIES: dict[str, list[tuple[str, float, float]]] = {
    "single-series": [
        ("1", ti, ti + delta) for ti in (10, 25, 40, 55, 70) for delta in (-10, 0, 10, 15)
    ],
    "grazing": [("1", ti, ti + delta) for ti in (70, 74, 78, 82, 86) for delta in (-12, -8, -4, 0)],
    "specular": [(str(k), ti, ti) for ti in (10, 25, 40, 55, 70) for k in (1, 2, 3, 4)],
}


def write_geometry_scene(directory: Path, geometry: str, params: Params, seed: int = 0) -> Path:
    """A scene of :data:`GEOMETRIES` ``geometry`` with default settings (no priors, errors or
    outputs named) and data simulated from its generative model at ``params``; returns the
    scene file. Each row's σ column is 6 % of its value."""
    from brdf_infer.scene import load_scene

    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    rows = GEOMETRIES[geometry]
    header = "series,sample,theta_i_deg,theta_s_deg,reflectance,reflectance_err"
    placeholder = [f"A,{m},{ti:g},{ts:g},1e-4,6e-6" for m, ti, ts in rows]
    (directory / "measurements.csv").write_text("\n".join([header, *placeholder]) + "\n")
    path = directory / "scene.toml"
    path.write_text(
        f'name = "{geometry}"\nmeasurements = "measurements.csv"\n'
        "[series.A]\naperture_diameter_mm = 7.5\naperture_distance_mm = 110.0\n"
    )
    scene = load_scene(path)
    template = scene.load_measurements()
    data = simulate_measurements(scene, template, params, seed=seed)
    lines = [
        f"A,{m},{ti:g},{ts:g},{r:.6e},{0.06 * r:.6e}"
        for (m, ti, ts), r in zip(rows, data.reflectance, strict=True)
    ]
    (directory / "measurements.csv").write_text("\n".join([header, *lines]) + "\n")
    return path


class SyntheticLab:
    """A virtual laboratory with a known coating: rows "measured" from the error model's
    equations drawn term by term (docs/error-model.md), not from the likelihood's Gaussian.

    For a row i of sample j in calibration group g at rotation setting k,

        ln R_i = ln R_pred(θi + ε_k, θs + s ε_k + η_i) + u_j + κ_g + e_i + ν_i,

    each effect drawn once and remembered: u_j ~ N(0, τ) per physical sample, κ_g ~ N(0, σ_cal)
    per calibration group (a series is a session: one reference measurement, Eq. 2), ε_k ~
    N(0, σ_rot) per (series, sample, θi) setting; per row η_i ~ N(0, σ_cam), the value's noise
    e_i ~ N(0, σ(R)/(R √n)) with n the images averaged into a row of its series, and the
    repeatability ν_i ~ N(0, σ_rep). The angle errors move the angles the forward model is
    evaluated at (no linearisation). Rows of a series measured in a later call continue that
    series' session; a series not seen before is a new session. The sample effects stay for
    the lab's life: new rows on a measured sample share its effect.

    Written separately from :class:`brdf_infer.posterior.PosteriorModel` (it never builds the
    covariance the likelihood marginalises), so a check that simulates here and fits there
    tests the one against the other.

    Args:
        scene: apertures, error model (every series a row may name must have an aperture).
        params: the coating (Eq. 7).
        sample_sd: τ [ln R] (unused without ``errors.hierarchical``).
        repeatability: σ_rep [ln R] (the scene's value where it fixes one).
        seed: of the lab's random numbers.
    """

    def __init__(
        self, scene: Scene, params: Params, sample_sd: float, repeatability: float, seed: int
    ):
        errors = scene.errors
        self.scene, self.params = scene, params
        self.sample_sd = sample_sd if errors.hierarchical else 0.0
        self.repeatability = (
            repeatability if errors.learns_repeatability else float(errors.repeatability)
        )
        self.rng = np.random.default_rng(seed)
        self.effects: dict[tuple, float] = {}

    def fork(self) -> SyntheticLab:
        """A copy that goes on from this lab's state (its effects and random numbers), for
        common random numbers across alternatives; the copies do not affect each other."""
        other = copy.copy(self)
        other.rng, other.effects = copy.deepcopy(self.rng), dict(self.effects)
        return other

    def _effect(self, key: tuple, sd: float) -> float:
        if key not in self.effects:
            self.effects[key] = float(sd * self.rng.standard_normal()) if sd > 0 else 0.0
        return self.effects[key]

    def log_values(self, rows: Measurements) -> np.ndarray:
        """Measured ln R of ``rows`` (their geometry, series, sample and σ column; the σ
        column and ``reflectance_rel`` are relative 1σ of one image)."""
        from brdf_infer.model import strumik_family
        from brdf_infer.predict.observations import family_log_reflectance_at

        errors, scene = self.scene.errors, self.scene
        angles = errors.angles_on
        count = len(rows)
        if rows.reflectance_err is not None:
            relative = rows.reflectance_err / rows.reflectance
        else:
            relative = np.full(count, errors.reflectance_rel)
        images = np.array([errors.images_of(str(s)) for s in rows.series], float)
        coupling = 1.0 if errors.rotation_coupling == "camera_follows" else -1.0
        theta_i = np.asarray(rows.theta_i_deg, float).copy()
        theta_s = np.asarray(rows.theta_s_deg, float).copy()
        offset = np.zeros(count)
        for i in range(count):
            series, sample = str(rows.series[i]), str(rows.sample[i])
            offset[i] += self._effect(("sample", sample), self.sample_sd)
            if errors.calibration == "per_series":
                offset[i] += self._effect(("calibration", series), errors.calibration_sd)
            elif errors.calibration == "per_sample":
                offset[i] += self._effect(("calibration", series, sample), errors.calibration_sd)
            if angles:
                key = ("rotation", series, sample, float(rows.theta_i_deg[i]))
                rotation = self._effect(key, errors.rotation_deg)
                theta_i[i] += rotation
                theta_s[i] += coupling * rotation + errors.camera_deg * self.rng.standard_normal()
        offset += relative / np.sqrt(images) * self.rng.standard_normal(count)
        offset += self.repeatability * self.rng.standard_normal(count)
        data = build_observation_model(scene, rows).data
        fold, constants = scene.model.fold, scene.model.constants
        member = strumik_family(fold, constants)
        physical = self.params._asdict()
        nominal = predicted_log_reflectance(self.params, data, fold, constants)
        moved = family_log_reflectance_at(member, theta_i, theta_s, physical, data)
        unmoved = family_log_reflectance_at(
            member, data.theta_i_deg, data.theta_s_deg, physical, data
        )
        return np.asarray(nominal + moved - unmoved) + offset

    def measure(self, rows: Measurements) -> Measurements:
        """``rows`` with measured values (:meth:`log_values`) and σ columns keeping each row's
        relative σ."""
        values = np.exp(self.log_values(rows))
        error = None
        if rows.reflectance_err is not None:
            error = rows.reflectance_err / rows.reflectance * values
        return replace(rows, reflectance=values, reflectance_err=error)


# A coating of another shape than Eq. (7)'s: a low-gloss black paint, a Lambertian floor
# (ρ_d = 3 %) under a specular ABg lobe (peak 1 sr⁻¹, knee at |β − β₀| = 0.032, g = 2), in the
# coordinates of the ``lambertian+abg`` family (brdf_infer.model); its rows are BRDF values of
# two samples at θi 10-70° and 64 θs each in the plane of incidence (512 rows).
PAINT_TRUTH = {
    "log_rho_d": float(np.log(0.03)),
    "log_peak": 0.0,
    "log_knee": float(np.log(1e-3) / 2.0),
    "g": 2.0,
}
PAINT_THETA_I_DEG = (10.0, 30.0, 50.0, 70.0)
PAINT_THETA_S_DEG = tuple(float(t) for t in np.linspace(-85.0, 85.0, 64))


def write_paint_scene(
    directory: Path, *, mirrored: bool = False, seed: int = 0, relative_sd: float = 0.05
) -> Path:
    """A scene of the planted paint (:data:`PAINT_TRUTH`): its BRDF rows (``quantity =
    "brdf"``, σ column ``relative_sd`` of each value) drawn from the scene's generative error
    model under the ``lambertian+abg`` family at the truth (sample effect 3 %, repeatability
    3 %); ``mirrored``: the file records −θs, the sign-convention slip of a lab whose forward
    side is negative. Returns the scene file (``paint.toml`` or ``paint-mirrored.toml``)."""
    from brdf_infer.model import family
    from brdf_infer.scene import load_scene

    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    name = "paint-mirrored" if mirrored else "paint"
    rows = [
        (sample, ti, ts)
        for sample in ("1", "2")
        for ti in PAINT_THETA_I_DEG
        for ts in PAINT_THETA_S_DEG
    ]
    header = "series,sample,theta_i_deg,theta_s_deg,brdf,brdf_err"
    csv = directory / f"{name}.csv"
    csv.write_text(
        "\n".join([header, *(f"A,{m},{ti:g},{ts:.6g},0.01,0.0005" for m, ti, ts in rows)]) + "\n"
    )
    scene_path = directory / f"{name}.toml"
    scene_path.write_text(
        f'name = "{name}"\nmeasurements = "{csv.name}"\n[series.A]\nquantity = "brdf"\n'
    )
    scene = load_scene(scene_path)
    values = np.exp(
        simulate_log_values(
            scene, scene.load_measurements(), family("lambertian+abg"), PAINT_TRUTH, seed=seed
        )
    )
    sign = -1.0 if mirrored else 1.0
    lines = [
        f"A,{m},{ti:g},{sign * ts:.6g},{v:.6e},{relative_sd * v:.6e}"
        for (m, ti, ts), v in zip(rows, values, strict=True)
    ]
    csv.write_text("\n".join([header, *lines]) + "\n")
    return scene_path


def simulate_log_values(
    scene: Scene,
    template: Measurements,
    member,
    truth: dict[str, float],
    *,
    sample_sd: float = 0.03,
    repeatability: float = 0.03,
    seed: int = 0,
) -> np.ndarray:
    """ln of the rows of ``template`` drawn from the scene's generative error model under the
    family ``member`` at its internal coordinates ``truth`` (by site; the learned scales set
    to ``sample_sd`` and ``repeatability``): the model the posterior fits, in simulation."""
    ensure_float64()
    import jax
    from numpyro import handlers
    from numpyro.infer import Predictive

    from brdf_infer.posterior import build_posterior_model

    model = build_posterior_model(scene, template, member)
    conditioned = handlers.condition(
        model, data={**truth, "sample_sd": sample_sd, "repeatability": repeatability}
    )
    draw = Predictive(conditioned, num_samples=1)(jax.random.PRNGKey(seed), mode="simulate")
    return np.asarray(draw["obs"][0])


HEMISPHERE_THETA_I_DEG = (10.0, 30.0, 50.0, 70.0)
HEMISPHERE_PHI_DEG = (165.0, 150.0, 135.0, 120.0, 105.0, 90.0)  # azimuths off the forward plane


def write_hemisphere_scene(
    directory: Path,
    params: Params,
    *,
    dphi_scale: float,
    seed: int = 0,
    relative_sd: float = 0.05,
    sample_sd: float = 0.03,
    errors: str = "",
    full: bool = False,
) -> Path:
    """A scatterometer-like scene of one sample measured over the hemisphere: at each θi of
    :data:`HEMISPHERE_THETA_I_DEG`, in-plane BRDF rows at θs −60° … 80° and rows out of the
    plane at polar angles 20–80° and the azimuths of :data:`HEMISPHERE_PHI_DEG` (forward plane
    at 180°) — or, ``full``, a scatterometer's whole grid: at θi 10°, 30°, 50°, 70° and 80°
    every polar angle 5°–85° (5° steps) at every azimuth 0°–350° (10° steps), 3060 rows —
    drawn from the scene's generative error model under Eqs. (7)-(8) at ``params``
    with Eq. (8)'s Δφ ``dphi_scale`` times the article's (sample effect drawn with τ =
    ``sample_sd``, repeatability 3 %; σ column ``relative_sd`` of each value; ``errors``: lines
    of the scene's ``[errors]`` table, which the simulation follows too). Returns the scene file
    (``hemisphere.toml``)."""
    from brdf_infer.model.coordinates import INTERNAL_NAMES, to_internal
    from brdf_infer.scene import load_scene

    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    if full:
        rows = [
            (ti, theta, f"{phi:g}")
            for ti in (10.0, 30.0, 50.0, 70.0, 80.0)
            for theta in np.arange(5.0, 86.0, 5.0)
            for phi in np.arange(0.0, 351.0, 10.0)
        ]
    else:
        rows = [
            (ti, ts, "")
            for ti in HEMISPHERE_THETA_I_DEG
            for ts in np.arange(-60.0, 81.0, 10.0)
            if ts != 0.0
        ]
        rows += [
            (ti, theta, f"{phi:g}")
            for ti in HEMISPHERE_THETA_I_DEG
            for theta in (20.0, 40.0, 60.0, 80.0)
            for phi in HEMISPHERE_PHI_DEG
        ]
    header = "series,sample,theta_i_deg,theta_s_deg,phi_s_deg,brdf,brdf_err"
    csv = directory / "hemisphere.csv"
    placeholder = [f"A,1,{ti:g},{ts:g},{phi},0.01,0.0005" for ti, ts, phi in rows]
    csv.write_text("\n".join([header, *placeholder]) + "\n")
    path = directory / "hemisphere.toml"
    path.write_text(
        'name = "hemisphere"\nmeasurements = "hemisphere.csv"\n[series.A]\nquantity = "brdf"\n'
        + (f"[errors]\n{errors}\n" if errors else "")
    )
    scene = load_scene(path)
    internal = dict(zip(INTERNAL_NAMES, np.asarray(to_internal(params)), strict=True))
    truth = {name: internal[name] for name in ("log_brdf0", "b1", "b2", "b3", "alpha", "t_s0")}
    truth["log_dphi_scale"] = float(np.log(dphi_scale))
    values = np.exp(
        simulate_log_values(
            scene, scene.load_measurements(), scene.family(), truth, sample_sd=sample_sd, seed=seed
        )
    )
    lines = [
        f"A,1,{ti:g},{ts:g},{phi},{v:.6e},{relative_sd * v:.6e}"
        for (ti, ts, phi), v in zip(rows, values, strict=True)
    ]
    csv.write_text("\n".join([header, *lines]) + "\n")
    return path
