"""Benchmark of the peers: the same posterior written in PyMC, sampled by nutpie and by PyMC's
NUTS, beside ``brdf-infer posterior`` (the optional extra ``peers``: ``pip install -e
".[peers]"``; the section is one line when pymc or nutpie is missing).

The PyMC model (:func:`pymc_model_from_arrays`) has the same rows, priors and error model as
the unwhitened NumPyro model (``build_posterior_model(..., reparametrise=False)``): the same
sites on the same coordinates (α, θs0/90°, ln BRDF0, b1, b2, b3, and the learned noise scales),
ln R of Eq. (7) in internal coordinates plus the row's ln(Ω cos θs) (and Eq. 10's fold where the
scene turns it on), and one multivariate normal of the rows' ln R with covariance
D + W Wᵀ (:func:`brdf_infer.error_model.covariance_factors`), written out as a dense 42 × 42
matrix for ``pm.MvNormal``. The linearised angle slopes are the analytic derivatives of ln R.
:func:`log_density_check` compares the two log densities at random points.

Every sampler runs in a fresh process (wall time end to end: interpreter start, imports,
building and compiling the model, sampling, saving the draws). A peer's process imports only
NumPy, PyMC and nutpie: the scene is read here and handed over as arrays
(:func:`model_arrays`), so the peers do not pay for importing JAX. This module imports nothing
but the standard library and NumPy at its top, so a peer's process can load it by path.
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

PEER_PACKAGES = ("pymc", "nutpie")
ANGLE_SCALE_DEG = 90.0  # brdf_infer.coordinates.ANGLE_SCALE_DEG (not imported: no JAX here)
DEG = math.pi / 180.0
PARAMETER_SITES = ("alpha", "t_s0", "log_brdf0", "b1", "b2", "b3")
PRIOR_NAMES = ("alpha", "theta_s0", "brdf0", "a1", "a2", "a3")  # the scene's name of each site
PRIOR_KINDS = ("fixed", "normal", "truncated_normal", "uniform")
QUANTITIES = ("brdf0", "alpha", "theta_s0", "tis70")
LABELS = {"brdf0": "BRDF0", "alpha": "α", "theta_s0": "θs0", "tis70": "TIS(70°)"}
ONE_THREAD = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
POINTS = 20  # of the log-density check

HEADERS = [
    "sampler",
    "BLAS threads",
    "cold [s]",
    "warm [s]",
    "sampling (warm) [s]",
    "min bulk ESS",
    "divergences",
    "leapfrog steps / draw",
    "ESS / warm s",
    "|Δ median| / sd: " + ", ".join(LABELS[q] for q in QUANTITIES),
]


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
    for name in PRIOR_NAMES:
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
        "sample_sd_prior": errors.sample_sd_prior if generative and errors.hierarchical else np.nan,
        "fixed_sample_sd": 0.0,
        "repeatability_prior": (
            errors.repeatability_sd_prior if generative and errors.learns_repeatability else np.nan
        ),
        "fixed_repeatability": (
            0.0 if not generative or errors.learns_repeatability else float(errors.repeatability)
        ),
        "rotation_deg": errors.rotation_deg if errors.angles_on else 0.0,
        "camera_deg": errors.camera_deg if errors.angles_on else 0.0,
    }
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

        alpha, t_s0, log_brdf0, b1, b2, b3 = (
            parameter(site, prior) for site, prior in zip(PARAMETER_SITES, a["priors"], strict=True)
        )
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
        calibration = float(a["calibration_sd"])
        rotation = float(a["rotation_deg"]) * g_rot
        diagonal = (
            a["sigma_row"] ** 2
            + repeatability**2
            + (g_cam * float(a["camera_deg"])) ** 2
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
            + calibration**2 * calibrations
            + pt.outer(rotation, rotation) * rotations
        )
        pm.MvNormal("obs", mu=mean, cov=covariance, observed=y)
    return model


def pymc_model(scene, measurements):
    """The PyMC model of ``scene`` on ``measurements``."""
    return pymc_model_from_arrays(model_arrays(scene, measurements))


# --- the log-density check ----------------------------------------------------------------


def check_points(scene, measurements, count: int = POINTS, seed: int = 0) -> list[dict]:
    """``count`` points of the unwhitened model's sites (constrained values): half drawn from
    the prior, half scattered about the published 121.6-nm parameters (where the likelihood
    dominates and the angle slopes matter)."""
    import jax
    from numpyro.infer import Predictive

    from brdf_infer.coordinates import to_internal
    from brdf_infer.params import UV_PAPER
    from brdf_infer.posterior import build_posterior_model

    model = build_posterior_model(scene, measurements, reparametrise=False)
    sites = _site_names(model)
    free = [site for site in PARAMETER_SITES if site in sites]
    noise = [site for site in ("sample_sd", "repeatability") if site in sites]
    prior = Predictive(model, num_samples=count, return_sites=[*free, *noise])(
        jax.random.PRNGKey(seed), model.data, mode="simulate"
    )
    centre = dict(
        zip(("log_brdf0", "b1", "b2", "b3", "alpha", "t_s0"), to_internal(UV_PAPER), strict=True)
    )
    spreads = {"alpha": 0.3, "t_s0": 0.03}  # others: 5 % of the value
    rng = np.random.default_rng(seed)
    points = []
    for k in range(count):
        point = {site: float(prior[site][k]) for site in [*free, *noise]}
        if k >= count // 2:
            for site in free:
                value = float(centre[site])
                point[site] = value + spreads.get(site, 0.05 * abs(value)) * rng.standard_normal()
            for site in noise:
                point[site] = 0.01 + abs(0.05 * rng.standard_normal())
        points.append(point)
    return points


def _site_names(model) -> set[str]:
    from numpyro import handlers

    seeded = handlers.seed(model, 0)
    trace = handlers.trace(seeded).get_trace(model.data)
    return {
        name
        for name, site in trace.items()
        if site["type"] == "sample" and not site.get("is_observed", False)
    }


def log_density_check(
    scene, measurements, count: int = POINTS, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """(ours, PyMC's) joint log density at :func:`check_points`: ours the unwhitened NumPyro
    model's (``numpyro.infer.util.log_density``, constrained values), PyMC's
    ``compile_logp(jacobian=False)`` with the value transforms removed. Equal up to a
    constant when the models are the same."""
    import jax.numpy as jnp
    from numpyro.infer.util import log_density
    from pymc.model.transform.conditioning import remove_value_transforms

    from brdf_infer.posterior import build_posterior_model

    ours_model = build_posterior_model(scene, measurements, reparametrise=False)
    peer = remove_value_transforms(pymc_model(scene, measurements))
    peer_logp = peer.compile_logp(jacobian=False)
    points = check_points(scene, measurements, count, seed)
    peer_sites = {variable.name for variable in peer.free_RVs}
    if peer_sites != set(points[0]):
        raise AssertionError(f"different sites: PyMC {peer_sites}, ours {set(points[0])}")
    ours, theirs = [], []
    for point in points:
        value, _ = log_density(
            ours_model, (ours_model.data,), {}, {k: jnp.asarray(v) for k, v in point.items()}
        )
        ours.append(float(value))
        theirs.append(float(peer_logp({k: np.asarray(v) for k, v in point.items()})))
    return np.array(ours), np.array(theirs)


def relative_spread(ours: np.ndarray, theirs: np.ndarray) -> float:
    """max over the points of |Δ − median Δ| / max(1, |ours|), Δ = theirs − ours: zero when the
    two log densities differ by one constant."""
    difference = theirs - ours
    return float(np.max(np.abs(difference - np.median(difference)) / np.maximum(1.0, np.abs(ours))))


# --- sampling in fresh processes ----------------------------------------------------------


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


def _run_child(arrays: Path, sampler: str, out: Path, settings, env: dict, blas: str = "auto"):
    """Wall time of one peer process and what it saved."""
    bootstrap = (
        "import importlib.util, sys; "
        f"spec = importlib.util.spec_from_file_location('_brdf_peers', {str(Path(__file__))!r}); "
        "module = sys.modules['_brdf_peers'] = importlib.util.module_from_spec(spec); "
        "spec.loader.exec_module(module); "
        "module._child(sys.argv[1:])"
    )
    argv = [str(arrays), sampler, str(out), *(str(s) for s in settings), blas]
    clock = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-c", bootstrap, *argv], capture_output=True, text=True, env=env
    )
    seconds = time.perf_counter() - clock
    if done.returncode != 0:
        raise RuntimeError(f"{sampler} failed:\n{done.stderr[-3000:]}")
    with np.load(out) as stored:
        result = {key: np.asarray(value) for key, value in stored.items()}
    return seconds, result


def _run_ours(scene: str, out: Path, cache: Path, settings, env: dict):
    """Wall time of one ``brdf-infer posterior SCENE --json`` process, its summary, draws and
    mean leapfrog steps per draw."""
    from brdf_infer._arviz import az

    chains, warmup, draws, seed = settings
    argv = [
        "posterior",
        scene,
        "--json",
        "--out",
        str(out),
        *("--chains", str(chains), "--warmup", str(warmup), "--draws", str(draws)),
        *("--seed", str(seed)),
    ]
    clock = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "brdf_infer", *argv],
        capture_output=True,
        text=True,
        env=dict(env, BRDF_INFER_CACHE=str(cache)),
    )
    seconds = time.perf_counter() - clock
    if done.returncode != 0:
        raise RuntimeError(f"brdf-infer posterior failed:\n{done.stderr[-3000:]}")
    summary = json.loads(done.stdout)
    idata = az.from_netcdf(out / "posterior.nc")
    sites = {name: np.asarray(idata.posterior[name]) for name in idata.posterior.data_vars}
    return seconds, summary, sites, float(idata.sample_stats["n_steps"].mean())


def physical_draws(sites: dict[str, np.ndarray], scene) -> dict[str, np.ndarray]:
    """BRDF0, α, θs0 and TIS(70°) of every draw, shape (chains, draws): from the paper-unit
    parameters (ours) or from the internal sites (a peer's), TIS by Eq. (9) with the scene's
    fold switch, as every TIS band of a run (``brdf_infer.posterior._bands``)."""
    from brdf_infer.coordinates import from_internal
    from brdf_infer.model import tis
    from brdf_infer.params import Params

    shape = next(iter(sites.values())).shape[:2]
    if "brdf0" in sites:
        params = Params(*(np.asarray(sites[name]) for name in Params._fields))
    else:
        internal = []
        for site, name in zip(PARAMETER_SITES, PRIOR_NAMES, strict=True):
            prior = scene.priors[name]
            scale = ANGLE_SCALE_DEG if name == "theta_s0" else 1.0
            internal.append(sites[site] if site in sites else np.full(shape, prior.value / scale))
        alpha, t_s0, log_brdf0, b1, b2, b3 = internal
        params = Params(
            *(
                np.asarray(value)
                for value in from_internal(np.stack([log_brdf0, b1, b2, b3, alpha, t_s0], -1))
            )
        )
    flat = Params(*(np.broadcast_to(value, shape).reshape(-1) for value in params))
    model = scene.model
    tis70 = np.asarray(tis(np.asarray(70.0), flat, model.fold, model.constants)).reshape(shape)
    return {
        "brdf0": np.asarray(params.brdf0).reshape(shape),
        "alpha": np.broadcast_to(params.alpha, shape),
        "theta_s0": np.broadcast_to(params.theta_s0, shape),
        "tis70": tis70,
    }


@dataclass(frozen=True)
class PeerRow:
    sampler: str
    blas: str
    cold: float
    warm: float | None  # None: no warm run (``repeat=0``)
    sampling: float  # of the warm run: the sampler's iterations (ours: summary seconds)
    min_ess: float
    divergences: int
    steps: float  # mean leapfrog steps per draw (after warmup)
    agreement: dict[str, float] | None  # |Δ median| / sd against ours; None for ours

    @property
    def cells(self) -> list[str]:
        agreement = (
            "reference"
            if self.agreement is None
            else ", ".join(f"{self.agreement[q]:.2f}" for q in QUANTITIES)
        )
        return [
            self.sampler,
            self.blas,
            f"{self.cold:.1f}",
            "–" if self.warm is None else f"{self.warm:.1f}",
            f"{self.sampling:.1f}",
            f"{self.min_ess:.0f}",
            str(self.divergences),
            f"{self.steps:.0f}",
            f"{self.min_ess / (self.cold if self.warm is None else self.warm):.1f}",
            agreement,
        ]


def _statistics(draws: dict[str, np.ndarray]) -> tuple[float, dict, dict]:
    from brdf_infer._arviz import az

    ess = min(float(az.ess(np.asarray(draws[q]), method="bulk")) for q in QUANTITIES)
    medians = {q: float(np.median(draws[q])) for q in QUANTITIES}
    sds = {q: float(np.std(draws[q])) for q in QUANTITIES}
    return ess, medians, sds


# (label, sampler, BLAS label, BLAS pinned to one thread by the environment). Unpinned,
# ``pm.sample`` still limits each of its worker processes to one BLAS thread itself
# (``blas_cores="auto"``); nutpie's threads and their OpenBLAS calls are left alone.
# (label, sampler, BLAS threads, pinned to one thread, warm run too). PyMC's NUTS needs
# ≈ 136 leapfrog steps per draw on this posterior (≈ 5–10 min a run on 2 cores), and with
# pip's default BLAS threading several times that: it runs cold only, pinned only.
PEER_RUNS = (
    ("nutpie (low-rank mass)", "nutpie-low-rank", "1", True, True),
    ("nutpie (low-rank mass)", "nutpie-low-rank", "default", False, False),
    ("nutpie (diagonal mass)", "nutpie", "1", True, True),
    ("PyMC NUTS", "pymc", "1", True, False),
)


def peer_rows(
    scene,
    quick: bool,
    progress=print,
    *,
    repeat: int = 1,
    draws: int | None = None,
    warmup: int | None = None,
) -> tuple[list[PeerRow], tuple[np.ndarray, np.ndarray]]:
    """The rows of the section, and (ours, PyMC's) log densities of the 20-point check.

    Each sampler runs 1 + ``repeat`` times in fresh processes: cold (empty compilation
    caches), then warm (the same caches; the best wall time of ``repeat``; none with 0: the
    full PyMC runs take long); the statistics
    come from the last warm run. 4 chains, seed 0; ``draws`` and ``warmup`` per chain default
    to ours (1000 and 1000; quick: 250 and 250).
    """
    draws = draws or (250 if quick else 1000)
    warmup = warmup or (250 if quick else 1000)
    settings = (4, warmup, draws, 0)
    measurements = scene.load_measurements()
    progress("  log density against PyMC's at 20 points ...")
    check = log_density_check(scene, measurements)
    base = {key: value for key, value in os.environ.items() if key not in ONE_THREAD}
    pinned = dict(base, **ONE_THREAD)
    rows = []
    with tempfile.TemporaryDirectory() as temporary:
        folder = Path(temporary)
        arrays = folder / "arrays.npz"
        np.savez(arrays, **model_arrays(scene, measurements))
        times = []
        for attempt in range(1 + repeat):
            progress(f"  brdf-infer posterior {scene.name}, {'cold' if attempt == 0 else 'warm'}")
            out = folder / f"ours_{attempt}"
            seconds, summary, sites, steps = _run_ours(
                str(scene.path), out, folder / "ours_cache", settings, pinned
            )
            times.append(seconds)
        reference = physical_draws(sites, scene)
        ess, medians, sds = _statistics(reference)
        rows.append(
            PeerRow(
                "ours (NumPyro NUTS, dense mass, whitened)",
                "1",
                times[0],
                min(times[1:], default=None),
                summary["seconds"]["sampling"],
                ess,
                int(summary["diagnostics"]["divergences"]),
                steps,
                None,
            )
        )
        for k, (label, sampler, blas, one_thread, warm) in enumerate(PEER_RUNS):
            caches = folder / f"caches_{k}"
            env = dict(
                pinned if one_thread else base,
                PYTENSOR_FLAGS=f"compiledir={caches / 'pytensor'}",
                NUMBA_CACHE_DIR=str(caches / "numba"),
            )
            times = []
            for attempt in range(1 + (repeat if warm else 0)):
                progress(f"  {label}, BLAS {blas}, {'cold' if attempt == 0 else 'warm'}")
                seconds, result = _run_child(
                    arrays, sampler, folder / f"{k}_{attempt}.npz", settings, env
                )
                times.append(seconds)
            sites = {
                key.removeprefix("site_"): value
                for key, value in result.items()
                if key.startswith("site_")
            }
            ess, peer_medians, _ = _statistics(physical_draws(sites, scene))
            rows.append(
                PeerRow(
                    label,
                    blas,
                    times[0],
                    min(times[1:], default=None),
                    float(result["seconds"][2]),
                    ess,
                    int(result["divergences"]),
                    float(result["steps"]),
                    {q: abs(peer_medians[q] - medians[q]) / sds[q] for q in QUANTITIES},
                )
            )
    return rows, check


def markdown_table(headers: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def peer_section(quick: bool, progress=print, *, repeat: int = 1) -> str:
    """The report's section (Markdown, ending in a blank line): one line when the ``peers``
    extra is missing."""
    # here, not at the top: the peers' processes load this file and must not import JAX
    from brdf_infer.bench._tables import markdown_table

    heading = "## Peers: nutpie and PyMC NUTS on the same posterior\n\n"
    missing = missing_peers()
    if missing:
        return (
            heading + f"Skipped: {' and '.join(missing)} not installed "
            '(`pip install -e ".[peers]"`).\n'
        )
    from brdf_infer.scene import load_scene

    progress("benchmark (peers): nutpie and PyMC NUTS ...")
    scene = load_scene("lya")
    rows, (ours, theirs) = peer_rows(scene, quick, progress, repeat=repeat)
    difference = theirs - ours
    spread = float(np.max(np.abs(difference - np.median(difference))))
    relative = relative_spread(ours, theirs)
    import nutpie
    import pymc

    draws = 250 if quick else 1000
    return (
        heading + f"The posterior of `lya` written in PyMC {pymc.__version__} "
        "(`brdf_infer.bench._peers`: the same 42 rows, priors and generative error model, "
        "one `pm.MvNormal` with covariance D + W Wᵀ and the analytic angle slopes) and sampled "
        f"by nutpie {nutpie.__version__} (numba backend) and by PyMC's NUTS (`pm.sample`), "
        f"4 chains × ({draws} warmup + {draws} draws), seed 0, against `brdf-infer posterior "
        "lya` (dense mass matrix on the whitened coordinates, the same posterior over the "
        "physical parameters). Log density against our unwhitened model at "
        f"{len(ours)} points (half from the prior, half near the posterior): PyMC − ours = "
        f"{float(np.median(difference)):.3g} everywhere to {spread:.1e} "
        f"(at most {relative:.1e} of the point's |log p|).\n\n"
        "Wall time end to end in a fresh process: interpreter start, imports, building and "
        "compiling the model, sampling, and the run's output (ours writes its whole run "
        "folder: PSIS-LOO, posterior predictive, bands; a peer saves its draws). Cold: empty "
        "compilation caches (ours: `BRDF_INFER_CACHE`, JAX's persistent cache; PyMC: "
        "PyTensor's `compiledir`, its C modules; nutpie: `compiledir` and `NUMBA_CACHE_DIR`); "
        f"warm: the same caches again{'' if repeat == 1 else f', best of {repeat}'}"
        f"{' (no warm runs: ESS per cold second)' if repeat == 0 else ''}. BLAS 1: "
        "`OMP_NUM_THREADS=OPENBLAS_NUM_THREADS=MKL_NUM_THREADS=1`; default: those unset "
        "(`pm.sample` then limits BLAS to its `cores` itself, `blas_cores='auto'`). Min bulk "
        "ESS over BRDF0, α, θs0 and TIS(70°) (Eq. 9 with Eq. 10 per draw); ESS / warm s "
        "divides it by the warm wall time; leapfrog steps per draw after warmup (the cost "
        "of a draw in gradients); |Δ median| / sd against ours, in our posterior "
        "sd. Rows without a warm run (PyMC NUTS, nutpie with default BLAS threading) divide "
        "by the cold time. PyMC NUTS with pip's default BLAS threading is not rerun here: "
        "measured earlier on this 2-core machine with the same model it took 2066 s against "
        "324 s pinned to one thread.\n\n"
        + markdown_table(HEADERS, [row.cells for row in rows])
        + "\n"
    )
