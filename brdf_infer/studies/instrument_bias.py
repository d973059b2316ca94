"""Does the instrument model matter? A synthetic experiment with known parameters.

The ray tracer (:mod:`brdf_infer.studies.raytrace`, an implementation separate from the kernel)
simulates what the setup measures at known parameters — dPs/Pi through AD (``aperture``) or
the Eq. (2) image ratio (``image``) — for every row of a scene; the scene's own generative
error model adds its noise (value noise, repeatability, sample and calibration effects,
angle errors) as multiplicative factors. Each data set is then analysed twice: with the
``point`` instrument of Eq. (6) and with the instrument that generated it. The point model's
large-data limit — its least-squares fit to the noise-free traced values — is what the ray
tracer predicts its posterior to centre on; the kernel's posterior should cover the truth.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from brdf_infer.model.params import Params, params_to_dict
from brdf_infer.scene import Scene, check_instrument
from brdf_infer.tables.measurements import Measurements

TRACED_QUANTITY = {"aperture": "simulated", "image": "image_ratio"}
QUANTITIES = ("brdf0", "alpha", "tis_70deg")


def traced_values(
    scene: Scene, measurements: Measurements, params: Params, instrument: str, rays: int, seed: int
) -> np.ndarray:
    """The ray tracer's value of ``instrument``'s quantity at every row (series by series,
    each with its own beam geometry)."""
    from brdf_infer.studies.raytrace import raytrace_series

    values = np.full(len(measurements), np.nan)
    for series in dict.fromkeys(measurements.series):
        setup = scene.setup_of(series)
        result = raytrace_series(replace(scene, raytrace=setup), measurements, params, rays, seed)
        lookup = {
            (r["theta_i_deg"], r["theta_s_deg"]): r[TRACED_QUANTITY[instrument]]
            for r in result.rows
        }
        for index in np.flatnonzero(measurements.series == series):
            key = (measurements.theta_i_deg[index], measurements.theta_s_deg[index])
            values[index] = lookup[key]
    return values


def synthetic_data(
    scene: Scene,
    measurements: Measurements,
    params: Params,
    truth: np.ndarray,
    seed: int,
    *,
    sample_sd: float = 0.03,
    repeatability: float = 0.05,
) -> Measurements:
    """Rows with reflectance = ``truth`` × the noise factors of the scene's generative error
    model (drawn at ``params`` with the given learned scales)."""
    from brdf_infer.predict.observations import build_observation_model
    from brdf_infer.studies.synthetic import simulate_measurements

    point = check_instrument(scene, "point")
    noisy = simulate_measurements(
        point, measurements, params, sample_sd=sample_sd, repeatability=repeatability, seed=seed
    )
    clean = np.exp(np.asarray(build_observation_model(point, measurements).log_reflectance(params)))
    return replace(measurements, reflectance=noisy.reflectance / clean * truth)


def _bias_quantities(scene: Scene, params: Params) -> dict[str, np.ndarray]:
    """BRDF0, α and TIS(70°) (with Eq. 10's folding where the scene's [model] fold has it, as
    every TIS band of a run)."""
    from brdf_infer.model import tis

    return {
        "brdf0": np.asarray(params.brdf0),
        "alpha": np.asarray(params.alpha),
        "tis_70deg": np.asarray(tis(70.0, params, scene.outputs.fold, scene.model.constants)),
    }


def bias_experiment(
    scene: Scene,
    measurements: Measurements,
    params: Params,
    generated_by: str,
    seeds: list[int],
    *,
    chains: int = 2,
    draws: int = 500,
    warmup: int = 500,
    rays: int = 2**17,
    progress: Callable[[str], None] = lambda message: None,
) -> dict[str, Any]:
    """Posteriors of ``point`` and of ``generated_by`` on data the ray tracer generated.

    Returns:
        ``{"generated_by", "params", "truth", "point_limit", "fits": [{"seed",
        "instrument", QUANTITY: {"median", "lo95", "hi95"}, "covers": {QUANTITY: bool}}],
        "coverage": {instrument: {QUANTITY: fraction of seeds}}}``.
    """
    from brdf_infer.fit.lsq import fit_lsq
    from brdf_infer.posterior import build_posterior_model, interval95, run_nuts

    truth_values = traced_values(scene, measurements, params, generated_by, rays, seed=7)
    truth = {k: float(v) for k, v in _bias_quantities(scene, params).items()}
    point_scene = check_instrument(scene, "point")
    limit = fit_lsq(point_scene, replace(measurements, reflectance=truth_values), starts=8)
    point_limit = {k: float(v) for k, v in _bias_quantities(scene, limit.params).items()}
    fits = []
    for seed in seeds:
        data = synthetic_data(scene, measurements, params, truth_values, seed)
        for instrument in ("point", generated_by):
            progress(f"  seed {seed}: posterior with the '{instrument}' instrument")
            model = build_posterior_model(check_instrument(scene, instrument), data)
            result = run_nuts(
                model, chains=chains, warmup=warmup, draws=draws, seed=seed, progress=False
            )
            drawn = Params(*(np.asarray(result.sites[n]).reshape(-1) for n in Params._fields))
            intervals = {k: interval95(v) for k, v in _bias_quantities(scene, drawn).items()}
            fits.append(
                {
                    "seed": seed,
                    "instrument": instrument,
                    **intervals,
                    "covers": {
                        k: intervals[k]["lo95"] <= truth[k] <= intervals[k]["hi95"]
                        for k in QUANTITIES
                    },
                    "divergences": int(np.sum(result.stats["diverging"])),
                }
            )
    coverage = {
        instrument: {
            k: float(np.mean([f["covers"][k] for f in fits if f["instrument"] == instrument]))
            for k in QUANTITIES
        }
        for instrument in ("point", generated_by)
    }
    return {
        "generated_by": generated_by,
        "params": params_to_dict(params),
        "truth": truth,
        "point_limit": point_limit,
        "fits": fits,
        "coverage": coverage,
    }
