"""Power-scaling sensitivity of a posterior to its prior and its likelihood (Kallioinen,
Paananen, Bürkner & Vehtari 2023, "Detecting and diagnosing prior and likelihood sensitivity
with power-scaling", Stat. Comput. 34, 57), through ArviZ's ``psens``.

Raising the prior (or the likelihood) to a power α near 1 and reweighting the draws by
importance sampling shows how far the posterior of each quantity would move: the cumulative
Jensen–Shannon distance per unit log α. psens needs, per draw, the log prior and the log
likelihood. The run's ``log_likelihood`` group does not serve: for rows correlated through the
shared effects it holds the leave-one-out conditionals log p(yᵢ | y₋ᵢ, θ) that PSIS-LOO needs,
whose sum is not the likelihood log p(y | θ). Both are therefore computed here from the draws:

* the log prior: the scene's priors on the coordinates the model samples (ln BRDF0, b1–b3, α,
  θs0/90°, and the half-normal priors of the learned noise scales), truncated to coatings that
  conserve energy (:mod:`brdf_infer.model._energy`: −∞ beyond, 0 for every posterior draw, so
  power-scaling is unchanged by it); latent angle errors
  (``angle_method = "latent"``) are part of the likelihood's structure and left out;
* the log likelihood: the joint normal of every row, N(y; μ, D + W Wᵀ) (independent rows for
  the ``spread`` model).

Diagnosis as in Kallioinen et al. (priorsense): sensitivity ≥ 0.05 to both prior and
likelihood is a possible prior–data conflict; to the prior but not the likelihood, a prior
that dominates a weak likelihood.
"""

from __future__ import annotations

import functools
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer._internal import arviz as az
from brdf_infer._internal.lowrank import log_density_over_scales, low_rank_normal_log_density
from brdf_infer._internal.stored_programs import StoredFunction
from brdf_infer.model import energy_log_factor
from brdf_infer.model.coordinates import ANGLE_SCALE_DEG
from brdf_infer.model.params import DPHI_NAME, PARAM_NAMES, Params
from brdf_infer.posterior._blocks import factor_columns, over_draw_blocks
from brdf_infer.posterior._likelihood import disjoint_columns, noise_prior
from brdf_infer.posterior._model import (
    DPHI_SITE,
    ENERGY_SITE,
    LINEAR,
    LINEAR_SITES,
    PosteriorModel,
    model_identity,
    prior_distribution,
)

SENSITIVITY_THRESHOLD = 0.05
# the sampled coordinate of each parameter's prior, and its scale (θs0 is sampled as θs0/90°)
_PRIOR_SITES = {
    **{name: (site, 1.0) for name, site in zip(LINEAR, LINEAR_SITES, strict=True)},
    "alpha": ("alpha", 1.0),
    "theta_s0": ("t_s0", ANGLE_SCALE_DEG),
    DPHI_NAME: (DPHI_SITE, 1.0),
}


def log_prior_draws(model: PosteriorModel, sites: dict[str, np.ndarray]) -> np.ndarray:
    """ln p(θ) of every draw (shape of the draws' leading axes), from the scene's priors on
    the sampled coordinates (module docstring). One compiled program: run op by op, its ~60
    small operations each cost a program of their own (traced, loaded from the cache)."""
    names = [
        name
        for name, prior in model.scene.priors.items()
        if not prior.fixed and (name != DPHI_NAME or model.family.dphi_free)
    ]
    needed = {_PRIOR_SITES[name][0] for name in names} | {"sample_sd", "repeatability"}
    if model.family.paper_parameters:
        needed |= set(model.family.parameters)
    used = {k: jnp.asarray(v) for k, v in sites.items() if k in needed}
    program = StoredFunction(
        lambda s: _log_prior(model, names, s), ("log prior", model_identity(model), names)
    )
    return np.asarray(program(used))


def _log_prior(model: PosteriorModel, names: list[str], sites: dict) -> jnp.ndarray:
    """:func:`log_prior_draws` of arrays (traced)."""
    total = jnp.zeros(jnp.shape(sites["alpha"]))
    for name in names:
        site, scale = _PRIOR_SITES[name]
        distribution = prior_distribution(model.scene.priors[name], scale)
        total += distribution.log_prob(sites[site])
    if model.family.paper_parameters:  # the physical prior's truncation (0 on the posterior)
        params = Params(*(sites[name] for name in PARAM_NAMES))
        total += energy_log_factor(params, model.family.constants_of(sites))
    errors = model.errors
    for site in ("sample_sd", "repeatability"):
        if site in sites:
            total += noise_prior(errors, site).log_prob(sites[site])
    return total


def log_likelihood_draws(model: PosteriorModel, sites: dict[str, np.ndarray]) -> np.ndarray:
    """ln p(y | θ) of every draw, the joint density of all rows (module docstring)."""
    shape = np.shape(sites[model.family.parameters[0]])
    flat = {
        k: np.reshape(v, (-1, *np.shape(v)[len(shape) :]))
        for k, v in sites.items()
        if k != ENERGY_SITE  # the physical prior's factor: no value to reshape
    }
    y = model.data.rows.log_reflectance
    program = _density_program(disjoint_columns(model.data))

    def joint(block):
        parts = model.draw_parts(block)
        if model.errors.model == "spread":
            normal = jax.scipy.stats.norm.logpdf(y, parts.mean, jnp.sqrt(parts.diagonal))
            return (jnp.sum(normal, axis=-1),)
        return (program(y, parts.mean, parts.factor, parts.diagonal),)

    rows = int(np.shape(y)[-1])
    (values,) = over_draw_blocks(joint, flat, rows, factor_columns(model.data.noise))
    return values.reshape(shape)


def sample_scale_likelihoods(
    model: PosteriorModel, sites: dict[str, np.ndarray], scales: np.ndarray
) -> np.ndarray | None:
    """ln p(y | θ, τ) of every draw of ``sites`` (draws on the leading axis) at every τ of
    ``scales`` (k,), τ the sample-to-sample scale ``sample_sd``: shape (draws, k), the rows
    read once per draw (``lowrank.log_density_over_scales``: τ multiplies W's sample
    columns only). None where τ also enters D (a sample of one row) or the error model is
    ``spread``: the caller evaluates :func:`log_likelihood_draws` at each τ instead."""
    noise = model.data.noise
    if model.errors.model == "spread" or np.any(np.asarray(noise.sample_alone) != 0):
        return None
    flat = {k: v for k, v in sites.items() if k != ENERGY_SITE}
    flat["sample_sd"] = np.ones(len(next(iter(flat.values()))))
    y = model.data.rows.log_reflectance
    program = _scales_program(disjoint_columns(model.data))

    def over_scales(block):
        parts = model.draw_parts(block)
        return (program(y, parts.mean, parts.factor, parts.diagonal, jnp.asarray(scales)),)

    rows = int(np.shape(y)[-1])
    (values,) = over_draw_blocks(over_scales, flat, rows, factor_columns(noise) + len(scales))
    return values


@functools.cache
def _scales_program(scaled: int):
    """``lowrank.log_density_over_scales`` vmapped over draws and jitted, once per
    number of sample columns."""
    return StoredFunction(
        jax.vmap(
            lambda y, m, w, d, s: log_density_over_scales(y, m, w, d, scaled, s),
            (None, 0, 0, 0, None),
        ),
        ("density over scales", scaled),
    )


@functools.cache
def _density_program(disjoint: int):
    """ln N(y; μ, D + W Wᵀ) of every draw (leading axis of μ, W, D), jitted once per number
    of disjoint columns (y an argument: one program for every data set of a shape; run
    eagerly it costs 6× more per call, and :func:`~._width._scale_marginal` calls it 24×)."""
    return StoredFunction(
        jax.vmap(
            lambda y, m, w, d: low_rank_normal_log_density(y, m, w, d, disjoint=disjoint),
            (None, 0, 0, 0),
        ),
        ("density", disjoint),
    )


def diagnosis(prior: float, likelihood: float) -> str:
    """The power-scaling diagnosis of one quantity (module docstring)."""
    if prior >= SENSITIVITY_THRESHOLD and likelihood >= SENSITIVITY_THRESHOLD:
        return "possible prior-data conflict"
    if prior >= SENSITIVITY_THRESHOLD:
        return "strong prior / weak likelihood"
    return "-"


def power_scaling(
    model: PosteriorModel,
    sites: dict[str, np.ndarray],
    quantities: dict[str, np.ndarray],
    log_likelihood: np.ndarray | None = None,
) -> dict[str, dict[str, float | str]]:
    """Prior and likelihood power-scaling sensitivity of each quantity.

    Args:
        model: the posterior model the draws are of.
        sites: its draws, (chains, draws, ...).
        quantities: the quantities to diagnose, each (chains, draws): parameters in paper
            units, noise scales, derived quantities such as a TIS.

        log_likelihood: :func:`log_likelihood_draws` of ``sites`` where the caller has it
            (None: computed here).

    Returns:
        ``{name: {"prior", "likelihood", "diagnosis"}}``.
    """
    idata = az.from_dict(
        posterior=quantities,
        log_likelihood={
            "y": log_likelihood_draws(model, sites) if log_likelihood is None else log_likelihood
        },
    )
    with warnings.catch_warnings():  # Pareto-smoothing notes on the importance weights
        warnings.simplefilter("ignore")
        idata.add_groups({"log_prior": {"prior": log_prior_draws(model, sites)}})
        prior = az.psens(idata, component="prior")
        likelihood = az.psens(idata, component="likelihood")
    result = {}
    for name in quantities:
        values = float(prior[name]), float(likelihood[name])
        result[name] = {
            "prior": values[0],
            "likelihood": values[1],
            "diagnosis": diagnosis(*values),
        }
    return result
