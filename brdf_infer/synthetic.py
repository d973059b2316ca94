"""Synthetic measurements from known parameters at a scene's measurement geometry."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from brdf_infer.measurements import Measurements
from brdf_infer.observations import build_observation_model, predicted_log_reflectance
from brdf_infer.params import Params
from brdf_infer.scene import Scene


def synthetic_measurements(
    scene: Scene,
    template: Measurements,
    params: Params,
    *,
    noise_rel: float = 0.0,
    seed: int = 0,
) -> Measurements:
    """Rows of ``template`` with reflectance predicted by ``params`` along the one forward
    path of the fits and the posterior (:func:`brdf_infer.observations.log_reflectance`:
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
    import jax
    from numpyro import handlers
    from numpyro.infer import Predictive

    from brdf_infer.coordinates import INTERNAL_NAMES, to_internal
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
