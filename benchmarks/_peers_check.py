"""The PyMC peer model checked against ours: both joint log densities at the same points, equal
up to one constant when the two models are the same (:mod:`._peers`)."""

from __future__ import annotations

import numpy as np

from benchmarks._peers import DPHI_SITE, PARAMETER_SITES, pymc_model

POINTS = 20  # of the log-density check


def check_points(scene, measurements, count: int = POINTS, seed: int = 0) -> list[dict]:
    """``count`` points of the unwhitened model's sites (constrained values): half drawn from
    the prior, half scattered about the published 121.6-nm parameters (where the likelihood
    dominates and the angle slopes matter). The prior's draws are those of its sites' own
    distributions kept where our prior is not zero: it refuses coatings that scatter more than
    they receive (TIS > 1), which the PyMC model leaves out (near the posterior, TIS ≈ 6 %, the
    two agree; a draw beyond it gave "inf" in the check before)."""
    import jax
    from numpyro.infer import Predictive

    from brdf_infer.model.coordinates import to_internal
    from brdf_infer.model.params import UV_PAPER
    from brdf_infer.posterior import build_posterior_model

    model = build_posterior_model(scene, measurements, reparametrise=False)
    sites = _site_names(model)
    free = [site for site in (*PARAMETER_SITES, DPHI_SITE) if site in sites]
    noise = [site for site in ("sample_sd", "repeatability") if site in sites]
    candidates = Predictive(model, num_samples=8 * count, return_sites=[*free, *noise])(
        jax.random.PRNGKey(seed), model.data, mode="simulate"
    )
    possible = []  # the first ``count`` candidates our prior allows (each one a traced density)
    for k in range(8 * count):
        if len(possible) == count:
            break
        if np.isfinite(_log_density(model, {s: candidates[s][k] for s in [*free, *noise]})):
            possible.append(k)
    prior = {site: np.asarray(candidates[site])[possible] for site in [*free, *noise]}
    centre = dict(
        zip(("log_brdf0", "b1", "b2", "b3", "alpha", "t_s0"), to_internal(UV_PAPER), strict=True)
    )
    centre[DPHI_SITE] = 0.0  # the article's Δφ
    spreads = {"alpha": 0.3, "t_s0": 0.03, DPHI_SITE: 0.25}  # others: 5 % of the value
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


def _log_density(model, point: dict) -> float:
    """Our unwhitened model's joint log density at ``point`` (constrained values)."""
    import jax.numpy as jnp
    from numpyro.infer.util import log_density

    value, _ = log_density(model, (model.data,), {}, {k: jnp.asarray(v) for k, v in point.items()})
    return float(value)


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
        ours.append(_log_density(ours_model, point))
        theirs.append(float(peer_logp({k: np.asarray(v) for k, v in point.items()})))
    return np.array(ours), np.array(theirs)


def relative_spread(ours: np.ndarray, theirs: np.ndarray) -> float:
    """max over the points of |Δ − median Δ| / max(1, |ours|), Δ = theirs − ours: zero when the
    two log densities differ by one constant."""
    difference = theirs - ours
    return float(np.max(np.abs(difference - np.median(difference)) / np.maximum(1.0, np.abs(ours))))
