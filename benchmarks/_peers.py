"""Benchmark of the peers: the same posterior written in PyMC, sampled by nutpie and by PyMC's
NUTS, beside ``brdf-infer posterior`` (the optional extra ``peers``: ``pip install -e
".[peers]"``; the section is one line when pymc or nutpie is missing).

The PyMC model (:func:`pymc_model_from_arrays`) has the same rows, priors and error model as
the unwhitened NumPyro model (``build_posterior_model(..., reparametrise=False)``): the same
sites on the same coordinates (α, θs0/90°, ln BRDF0, b1, b2, b3, and the learned noise scales),
ln R of Eq. (7) in internal coordinates plus the row's ln(Ω cos θs) (and Eq. 10's fold where the
scene turns it on), and one multivariate normal of the rows' ln R with covariance
D + W Wᵀ (:func:`brdf_infer.model.error_model.covariance_factors`), written out as a dense 42 × 42
matrix for ``pm.MvNormal``. The linearised angle slopes are the analytic derivatives of ln R.
:func:`benchmarks._peers_check.log_density_check` compares the two log densities at
random points.

Every sampler runs in a fresh process (wall time end to end: interpreter start, imports,
building and compiling the model, sampling, saving the draws; :mod:`._peers_runs`). A peer's
process imports only NumPy, PyMC and nutpie: the scene is read here and handed over as arrays
(:func:`model_arrays`), so the peers do not pay for importing JAX. This module imports nothing
but the standard library and NumPy at its top, so a peer's process can load it by path and run
:func:`_child`; the report's section is :mod:`._peers_section`.
"""

from __future__ import annotations

import importlib.util
import math
import os
import time

import numpy as np

PEER_PACKAGES = ("pymc", "nutpie")
ANGLE_SCALE_DEG = 90.0  # brdf_infer.model.coordinates.ANGLE_SCALE_DEG (not imported: no JAX here)
DEG = math.pi / 180.0
PARAMETER_SITES = ("alpha", "t_s0", "log_brdf0", "b1", "b2", "b3")
PRIOR_NAMES = ("alpha", "theta_s0", "brdf0", "a1", "a2", "a3")  # the scene's name of each site
PRIOR_KINDS = ("fixed", "normal", "truncated_normal", "uniform")
DPHI_SITE = "log_dphi_scale"  # brdf_infer.posterior._model.DPHI_SITE: ln of Eq. (8)'s Δφ factor


def missing_peers() -> list[str]:
    """The packages of the ``peers`` extra that cannot be imported here."""
    return [name for name in PEER_PACKAGES if importlib.util.find_spec(name) is None]


# --- the model in PyMC --------------------------------------------------------------------


def model_arrays(scene, measurements) -> dict[str, np.ndarray]:
    """Everything the PyMC model needs, as plain arrays (saved to a file for a fresh process).

    Taken from the unwhitened posterior model of ``scene`` on ``measurements`` (its rows, noise
    layout, priors and error settings), so that both models read the same numbers.

    Raises:
        NotImplementedError: what the PyMC model does not cover: rows out of the plane of
            incidence, instrument kernels, latent angles.
    """
    from scipy.special import log_ndtr

    from brdf_infer.posterior import build_posterior_model

    model = build_posterior_model(scene, measurements, reparametrise=False)
    rows, noise, errors = model.data.rows, model.data.noise, scene.errors
    if rows.kernel is not None:
        raise NotImplementedError("the PyMC peer model has no instrument kernels (point only)")
    if rows.phi_s_deg is not None and np.isfinite(np.asarray(rows.phi_s_deg)).any():
        raise NotImplementedError("the PyMC peer model has no rows out of the plane")
    if errors.angles_on and errors.angle_method != "linearised":
        raise NotImplementedError("the PyMC peer model linearises the angle errors")
    if errors.sample_sd_log_kde is not None:
        raise NotImplementedError("the PyMC peer model has no τ prior from another run")
    theta_i, theta_s = np.asarray(rows.theta_i_deg), np.asarray(rows.theta_s_deg)
    # parts that do not depend on the parameters: ln Ω (+ ln cos θs), Eq. (10)'s fold, and their
    # derivatives in θs (ln Ω is constant in the angles; ln cos θs only on raw-reflectance rows)
    offset = np.asarray(rows.log_aperture, float).copy()
    slope_s = -np.asarray(rows.cos_weight) * np.tan(theta_s * DEG) * DEG
    if scene.model.fold:
        constants = scene.model.constants
        forward = theta_s >= 0
        u = -math.sqrt(2.0) * constants.fold_a_per_deg * (theta_s - constants.fold_theta_sf_deg)
        log_cdf = log_ndtr(u)
        log_pdf = -0.5 * u**2 - 0.5 * math.log(2.0 * math.pi)
        offset += np.where(forward, log_cdf, 0.0)
        slope_s += np.where(
            forward,
            -math.sqrt(2.0) * constants.fold_a_per_deg * np.exp(log_pdf - log_cdf),
            0.0,
        )
    priors = []
    # Eq. (8)'s out-of-plane width, a parameter where uncertain: a prior-only dimension here
    # (every row lies in the plane, where Δφ does not enter), sampled by both models alike
    widths = ("dphi_scale",) if model.family.dphi_free else ()
    for name in (*PRIOR_NAMES, *widths):
        prior = scene.priors[name]
        scale = ANGLE_SCALE_DEG if name == "theta_s0" else 1.0
        priors.append(
            [
                PRIOR_KINDS.index(prior.kind),
                prior.loc / scale,
                prior.scale / scale,
                prior.lower / scale,
                prior.upper / scale,
                prior.value / scale,
            ]
        )
    generative = errors.model == "generative"
    settings = {
        "generative": float(generative),
        "angles": float(errors.angles_on),
        # half-normal prior scale of a learned scale, NaN where fixed (at "fixed_*")
        "sample_sd_prior": errors.sample_sd_prior if errors.learns_sample_sd else np.nan,
        "fixed_sample_sd": 0.0 if errors.learns_sample_sd else float(errors.stated_sample_sd),
        "repeatability_prior": (
            errors.repeatability_sd_prior if generative and errors.learns_repeatability else np.nan
        ),
        "fixed_repeatability": (
            0.0 if not generative or errors.learns_repeatability else float(errors.repeatability)
        ),
    }  # σ_cal, σ_rot and σ_cam per row are the noise layout's (0 where off)
    return {
        "t": theta_i / ANGLE_SCALE_DEG,
        "theta_s_internal": theta_s / ANGLE_SCALE_DEG,
        "offset": offset,
        "slope_s": slope_s,
        "log_reflectance": np.asarray(rows.log_reflectance, float),
        "priors": np.array(priors, float),
        **{key: np.asarray(value, float) for key, value in noise._asdict().items()},
        **{key: np.asarray(value, float) for key, value in settings.items()},
    }


def pymc_model_from_arrays(arrays: dict[str, np.ndarray]):
    """The PyMC model of :func:`model_arrays`' output (see the module docstring)."""
    import pymc as pm
    import pytensor.tensor as pt

    a = {key: np.asarray(value) for key, value in arrays.items()}
    with pm.Model() as model:

        def noise_scale(site: str) -> object:
            prior = float(a[f"{site}_prior"])
            if math.isnan(prior):
                return pt.constant(float(a[f"fixed_{site}"]))
            return pm.HalfNormal(site, sigma=prior)

        sample_sd, repeatability = noise_scale("sample_sd"), noise_scale("repeatability")

        def parameter(site: str, prior) -> object:
            kind, loc, sd, low, high, value = prior
            kind = PRIOR_KINDS[int(kind)]
            if kind == "fixed":
                return pt.constant(value)
            if kind == "normal":
                return pm.Normal(site, mu=loc, sigma=sd)
            if kind == "uniform":
                return pm.Uniform(site, lower=low, upper=high)
            return pm.TruncatedNormal(
                site,
                mu=loc,
                sigma=sd,
                lower=low if math.isfinite(low) else None,
                upper=high if math.isfinite(high) else None,
            )

        sites = zip(PARAMETER_SITES, a["priors"], strict=False)  # Eq. (8)'s width after them
        alpha, t_s0, log_brdf0, b1, b2, b3 = (parameter(site, prior) for site, prior in sites)
        if len(a["priors"]) > len(PARAMETER_SITES):  # Eq. (8)'s width: its prior only
            parameter(DPHI_SITE, a["priors"][len(PARAMETER_SITES)])
        # Eq. (7) in internal coordinates: ln BRDF0 + b1 t x' + (b2 t + b3 t²) x'^α, x' > 0
        t = a["t"]
        x = a["theta_s_internal"] - t_s0
        positive = pt.gt(x, 0.0)
        log_x = pt.log(pt.switch(positive, x, 1.0))
        x_linear = pt.switch(positive, x, 0.0)
        x_alpha = pt.switch(positive, pt.exp(alpha * log_x), 0.0)
        mean = a["offset"] + log_brdf0 + b1 * t * x_linear + (b2 * t + b3 * t**2) * x_alpha
        y = a["log_reflectance"]
        if not float(a["generative"]):  # the "spread" error model: independent rows
            pm.Normal("obs", mu=mean, sigma=a["sigma_row"], observed=y)
            return model
        if float(a["angles"]):  # ∂ ln R / ∂θi and ∂ ln R / ∂θs per degree
            x_alpha_1 = pt.switch(positive, pt.exp((alpha - 1.0) * log_x), 0.0)
            d_i = (b1 * x_linear + (b2 + 2.0 * b3 * t) * x_alpha) / ANGLE_SCALE_DEG
            d_s = (
                b1 * t * positive + (b2 * t + b3 * t**2) * alpha * x_alpha_1
            ) / ANGLE_SCALE_DEG + a["slope_s"]
            g_rot, g_cam = d_i + a["theta_s_per_rotation"] * d_s, d_s
        else:
            g_rot = g_cam = pt.zeros_like(mean)
        calibration = a["calibration_sd"]  # per row, as the rotation and camera scales
        rotation = a["rotation_deg"] * g_rot
        diagonal = (
            a["sigma_row"] ** 2
            + repeatability**2
            + (g_cam * a["camera_deg"]) ** 2
            + a["sample_alone"] * sample_sd**2
            + a["calibration_alone"] * calibration**2
            + a["rotation_alone"] * rotation**2
        )
        samples, calibrations, rotations = (
            a[key] @ a[key].T
            for key in ("sample_members", "calibration_members", "rotation_members")
        )
        covariance = (
            pt.diag(diagonal)
            + sample_sd**2 * samples
            + np.outer(calibration, calibration) * calibrations
            + pt.outer(rotation, rotation) * rotations
        )
        pm.MvNormal("obs", mu=mean, cov=covariance, observed=y)
    return model


def pymc_model(scene, measurements):
    """The PyMC model of ``scene`` on ``measurements``."""
    return pymc_model_from_arrays(model_arrays(scene, measurements))


# --- a peer's process ----------------------------------------------------------------------


def _child(argv: list[str]) -> None:
    """A peer's process: ``ARRAYS.npz SAMPLER OUT.npz CHAINS WARMUP DRAWS SEED [BLAS]`` with
    SAMPLER ``pymc``, ``nutpie`` or ``nutpie-low-rank``; BLAS ``auto`` (``pm.sample``'s
    default) or ``none`` (``blas_cores=None``, leave the BLAS alone)."""
    arrays_path, sampler, out_path = argv[:3]
    chains, warmup, draws, seed = (int(value) for value in argv[3:7])
    blas = argv[7] if len(argv) > 7 else "auto"
    clock = time.perf_counter()
    import pymc as pm

    with np.load(arrays_path) as stored:
        model = pymc_model_from_arrays(dict(stored))
    started = time.perf_counter()
    cores = min(chains, os.cpu_count() or 1)
    if sampler == "pymc":
        idata = pm.sample(
            draws=draws,
            tune=warmup,
            chains=chains,
            cores=cores,
            random_seed=seed,
            progressbar=False,
            compute_convergence_checks=False,
            blas_cores="auto" if blas == "auto" else None,
            model=model,
        )
        compiled_at = started
    else:
        import nutpie

        compiled = nutpie.compile_pymc_model(model, backend="numba")
        compiled_at = time.perf_counter()
        idata = nutpie.sample(
            compiled,
            draws=draws,
            tune=warmup,
            chains=chains,
            cores=cores,
            seed=seed,
            save_warmup=False,
            progress_bar=False,
            low_rank_modified_mass_matrix=sampler == "nutpie-low-rank",
        )
    done = time.perf_counter()
    posterior = idata.posterior
    sites = {name: np.asarray(posterior[name]) for name in posterior.data_vars}
    np.savez(
        out_path,
        divergences=int(np.asarray(idata.sample_stats["diverging"]).sum()),
        steps=float(np.asarray(idata.sample_stats["n_steps"]).mean()),
        seconds=np.array([started - clock, compiled_at - started, done - compiled_at]),
        **{f"site_{name}": values for name, values in sites.items()},
    )
