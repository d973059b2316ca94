"""Synthetic measurements from known parameters at a scene's measurement geometry."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from brdf_infer.measurements import Measurements
from brdf_infer.model import brdf_inplane, brdf_to_reflectance
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
    """Rows of ``template`` with reflectance predicted by ``params`` (Eqs. 6, 7, 10).

    Args:
        scene: apertures and model components (folding).
        template: the geometry (series, sample, θi, θs) to reproduce.
        params: the generating parameters, paper units.
        noise_rel: 1σ of multiplicative log-normal noise, e.g. 0.065 [-].
        seed: noise seed.

    Returns:
        A table like ``template`` with new ``reflectance`` and ``reflectance_err = noise_rel·R``.
    """
    d, r = scene.apertures(template)
    brdf = brdf_inplane(
        template.theta_i_deg, template.theta_s_deg, params, scene.model.fold, scene.model.constants
    )
    clean = np.asarray(brdf_to_reflectance(brdf, template.theta_s_deg, d, r))
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
