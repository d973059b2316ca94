"""What carries the width of each headline interval: the data, the prior, or an assumption of
the error model.

For each headline quantity (TIS at the scene's incidence angles and at 70°, π·BRDF0) a run
reports its 95 % interval and

* **without each assumption** the scene's error model makes — the per-series calibration, the
  sample-to-sample effect, the angle errors — the interval the same data would give were that
  noise source absent, and its width as a fraction of the run's (``ratio``; 1 − ratio is the
  share of the width the assumption carries). The run's draws are reweighted to each variant's
  likelihood by Pareto-smoothed importance sampling (Vehtari et al. 2024, "Pareto smoothed
  importance sampling", JMLR 25, 72): the weight of a draw θ is p_variant(y | θ) / p(y | θ), the
  priors being the same, and the Pareto k̂ of the weights says whether that is reliable. Where
  k̂ > :func:`~brdf_infer.verdict.pareto_k_limit` of the draws (0.7 from 2200 draws, 0.67 at
  a table's 1000) the variant is sampled anew (``refit``) instead
  (:func:`brdf_infer.posterior._answer.answer_records`): by importance sampling from a
  Student-t fitted to the run's draws, else by the run's own sampler, into
  :data:`brdf_infer.posterior._answer.REFIT_CHAINS` × ``REFIT_DRAWS`` (2 × 500) draws. Their size
  is set by the Monte Carlo error the interval needs: an endpoint q of a 95 % interval from an
  effective sample size n has standard error √(0.025 · 0.975 / n) / p(q) ≈ 2.7 σ / √n for a
  normal quantity, so the width 3.92 σ has a relative standard error ≈ 0.96 / √n, and the
  width ratio about 0.03 at n ≈ 1000 (its endpoints' ESS is ≈ 0.8–1 per draw on lya). The
  record keeps the refit's settings and each endpoint's MC standard error (ArviZ's quantile
  ``mcse``; ``refit``). Without the
  sample effect its scale τ no longer enters the likelihood, and the draws' τ, concentrated
  where the run's data put it, would make the weights p_variant(y | θ) / p(y | θ, τ) needlessly
  variable (k̂ ≈ 1.1 on the bundled data); the weight of θ is taken against the run's likelihood
  with τ integrated out over its prior instead, p_variant(y | θ) / ∫ p(y | θ, τ) p(τ) dτ (the
  marginal of the run's posterior in θ is then the proposal), by Gauss–Legendre quadrature in
  ln τ over the central 99 % of the run's τ draws widened fourfold each side
  (:data:`TAU_NODES`), and below that range the likelihood at its lower end times the prior's
  mass there (to O(τ²): τ enters the covariance squared).
* **the prior predictive** interval of the same quantity (draws of the physical prior,
  :func:`brdf_infer.posterior.prior_draws`) and the prior's probability of a value above 1.

Latent angle errors (``angle_method = "latent"``) are sampled, not marginalised; there the
variants are not computed (the reason is recorded).
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.special import erf, logsumexp
from scipy.stats import norm

from brdf_infer._internal import arviz as az
from brdf_infer.model import ModelFamily
from brdf_infer.model.error_model import ErrorSettings
from brdf_infer.posterior._model import PosteriorModel, build_posterior_model
from brdf_infer.posterior._power_scaling import log_likelihood_draws, sample_scale_likelihoods
from brdf_infer.tables.measurements import Measurements
from brdf_infer.verdict import pareto_k_limit

HEADLINE_TIS_DEG = 70.0  # the article's TIS angle (Sec. 7)
TAU_NODES = 24  # Gauss–Legendre nodes in ln τ (module docstring)


@dataclass(frozen=True)
class Assumption:
    """One assumption of the error model, and the ``[errors]`` keys that remove it."""

    name: str
    words: str
    changes: dict[str, Any]
    applies: Callable[[ErrorSettings], bool]
    unused_site: str | None = None  # a learned scale the variant no longer has


ASSUMPTIONS = (
    Assumption(  # a zero scale, not calibration = "none": the run's programs serve it
        "calibration",
        "the calibration",
        {"calibration_rel": 0.0},
        lambda e: e.calibration_sd > 0,
    ),
    Assumption(
        "sample_effect",
        "the sample-to-sample effect",
        {"hierarchical": False},
        lambda e: e.model == "generative" and e.hierarchical,
        "sample_sd",
    ),
    Assumption(  # zero scales, not propagate_angles = False: the run's program serves it
        "angle_errors",
        "the angle errors",
        {"rotation_deg": 0.0, "camera_deg": 0.0},
        lambda e: e.angles_on,
    ),
)


@dataclass(frozen=True)
class Refitted:
    """A variant's headline quantities from a new posterior of its own (a refit).

    Attributes:
        headline: every draw of each headline quantity, (chains, draws) [fraction].
        settings: the refit's ``chains``, ``draws`` (per chain) and ``sampler``
            (``importance`` with its ``pareto_k`` and ``ess``, ``laplace``, or ``nuts`` with
            its ``warmup``).
    """

    headline: dict[str, np.ndarray]
    settings: dict[str, int | str]

    def record(self, name: str) -> dict[str, Any]:
        """The refit's settings and the MC standard errors of ``name``'s 95 % endpoints
        (``mcse_lo95``, ``mcse_hi95``, same units as the quantity; ArviZ's quantile MCSE,
        from the effective sample size at each quantile)."""
        values = self.headline[name]
        mcse = {
            key: float(az.mcse(values, method="quantile", prob=prob))
            for key, prob in (("mcse_lo95", 0.025), ("mcse_hi95", 0.975))
        }
        return {**self.settings, **mcse}


def tis_quantity(theta_i_deg: float) -> str:
    """The name of TIS(θi) among the headline quantities, e.g. ``tis_70deg``."""
    return f"tis_{float(theta_i_deg):g}deg"


def headline_draws(
    member: ModelFamily, physical: dict[str, np.ndarray], tis_angles: Sequence[float]
) -> dict[str, np.ndarray]:
    """Every draw (flattened) of each headline quantity: TIS at ``tis_angles`` [deg] (with the
    family's fold, as its bands) where the family's TIS is Eq. (9), π·BRDF0 where it has
    Eq. (7)'s parameters. Fractions."""
    values: dict[str, np.ndarray] = {}
    if member.log_tis_draws is not None and len(tis_angles):
        angles = np.asarray(sorted(set(float(a) for a in tis_angles)))
        flat = {k: np.asarray(v).reshape(-1) for k, v in physical.items()}
        tis = np.exp(np.asarray(member.log_tis_draws(angles, flat)))
        values.update({tis_quantity(a): tis[:, k] for k, a in enumerate(angles)})
    if member.paper_parameters:
        values["pi_brdf0"] = np.pi * np.asarray(physical["brdf0"]).reshape(-1)
    return values


def weighted_interval(values: np.ndarray, log_weights: np.ndarray) -> tuple[float, float]:
    """The central 95 % interval of ``values`` under normalised ``exp(log_weights)`` (the
    weighted empirical CDF, interpolated at mid-points)."""
    order = np.argsort(values)
    weights = np.exp(log_weights[order] - np.max(log_weights))
    cdf = (np.cumsum(weights) - 0.5 * weights) / np.sum(weights)
    low, high = np.interp([0.025, 0.975], cdf, values[order])
    return float(low), float(high)


def _interval(values: np.ndarray) -> tuple[float, float]:
    low, high = np.quantile(values, [0.025, 0.975])
    return float(low), float(high)


def smoothed_log_weights(log_ratio: np.ndarray) -> tuple[np.ndarray, float]:
    """Pareto-smoothed log importance weights of draws and their k̂ (ArviZ ``psislw``)."""
    with warnings.catch_warnings():  # ArviZ warns on k̂ > 0.7; the caller reports it
        warnings.simplefilter("ignore")
        log_weights, k_hat = az.psislw(np.asarray(log_ratio, float) - np.max(log_ratio))
    return np.asarray(log_weights), float(k_hat)


def _scale_marginal(model: PosteriorModel, flat: dict[str, np.ndarray], site: str) -> np.ndarray:
    """ln ∫ p(y | θ, τ) p(τ) dτ of every draw's θ, τ the learned scale ``site`` under its
    half-normal prior (module docstring)."""
    draws = np.asarray(flat[site], float)
    prior_scale = model.errors.noise_prior_scale(site)
    # the draws' central 99 %, widened fourfold each side: the extreme draws of a half-normal
    # reach 1e-6, and nodes spread to there left too few where the mass is (0.008 in ln)
    low = np.log(max(np.quantile(draws, 0.005), 1e-12) / 4.0)
    high = max(np.log(max(np.quantile(draws, 0.995), 1e-12) * 4.0), low + np.log(16.0))
    x, w = np.polynomial.legendre.leggauss(TAU_NODES)
    log_tau = low + 0.5 * (high - low) * (x + 1.0)
    tau = np.exp(log_tau)
    # p(τ) dτ = p(τ) τ d ln τ, half-normal p(τ)
    log_prior = np.log(2.0) + norm.logpdf(tau, 0.0, prior_scale) + log_tau
    log_step = np.log(0.5 * (high - low) * w)
    floor = np.exp(low)
    scales = np.append(tau, floor)
    terms = sample_scale_likelihoods(model, flat, scales) if site == "sample_sd" else None
    if terms is None:
        terms = np.stack(
            [log_likelihood_draws(model, {**flat, site: np.full_like(draws, v)}) for v in scales],
            axis=1,
        )
    inside = logsumexp(terms[:, :-1].T + (log_prior + log_step)[:, None], axis=0)
    # τ in (0, e^low): the likelihood there is its value at e^low to O(τ²) (τ enters the
    # covariance as τ²), times the prior's mass below, erf(e^low / (s √2))
    below = terms[:, -1]
    return np.logaddexp(inside, below + np.log(erf(floor / (prior_scale * np.sqrt(2.0)))))


def variant_model(
    model: PosteriorModel, measurements: Measurements, assumption: Assumption
) -> PosteriorModel:
    """``model`` with ``assumption`` removed from its scene's error model."""
    scene = model.scene
    errors = dataclasses.replace(scene.errors, **assumption.changes)
    return build_posterior_model(
        dataclasses.replace(scene, errors=errors), measurements, model.family
    )


def _intervals(
    headline: dict[str, np.ndarray], prior_headline: dict[str, np.ndarray]
) -> dict[str, Any]:
    """Each quantity's 95 % interval and its prior predictive one (``without`` left empty)."""
    result: dict[str, Any] = {}
    for name, values in headline.items():
        low, high = _interval(values)
        prior = prior_headline[name]
        prior_low, prior_high = _interval(prior)
        result[name] = {
            "lo95": low,
            "hi95": high,
            "prior": {
                "lo95": prior_low,
                "hi95": prior_high,
                "p_above_1": float(np.mean(prior > 1.0)),
            },
            "without": {},
        }
    return result


def width_attribution(
    model: PosteriorModel,
    measurements: Measurements,
    sites: dict[str, np.ndarray],
    headline: dict[str, np.ndarray],
    prior_headline: dict[str, np.ndarray],
    refit: Callable[[PosteriorModel], Refitted] | None = None,
    log_likelihood: np.ndarray | None = None,
    run_headline: dict[str, np.ndarray] | None = None,
) -> dict[str, Any]:
    """The ``"width"`` record of a run (module docstring).

    Args:
        model: the run's posterior model.
        measurements: its rows.
        sites: its draws, (chains, draws, ...).
        headline: every draw (flattened) of each headline quantity (:func:`headline_draws`).
        prior_headline: the same quantities over draws of the physical prior.
        refit: a variant model's headline draws from a new posterior (:class:`Refitted`) where
            the weights' k̂ exceeds their limit (None: reported with k̂, no interval).
        log_likelihood: the run's joint ln p(y | θ) of every draw (None: computed here).
        run_headline: where ``sites`` are a thinned set of the draws (a large table), the
            headline over all: the run's intervals; each ratio is over the thinned width.

    Returns:
        ``{QUANTITY: {"lo95", "hi95", "prior": {"lo95", "hi95", "p_above_1"}, "without":
        {ASSUMPTION: {"lo95", "hi95", "ratio", "pareto_k", "method", "words"}}}}`` (an
        unreliable variant's interval and ratio None; a refitted one's also ``"refit"``:
        :meth:`Refitted.record`) and, where no variant was computed, ``"without_note"``.
    """
    result = _intervals(headline if run_headline is None else run_headline, prior_headline)
    widths = {name: np.ptp(_interval(values)) for name, values in headline.items()}
    errors = model.errors
    if errors.angles_on and errors.angle_method == "latent":
        for entry in result.values():
            entry["without_note"] = "not computed: the angle errors are latent variables"
        return result
    flat = {k: np.reshape(v, (-1, *np.shape(v)[2:])) for k, v in sites.items()}
    base = (
        log_likelihood_draws(model, flat)
        if log_likelihood is None
        else np.reshape(log_likelihood, -1)
    )
    for assumption in ASSUMPTIONS:
        if not assumption.applies(errors):
            continue
        variant = variant_model(model, measurements, assumption)
        dropped = assumption.unused_site
        used = {k: v for k, v in flat.items() if k != dropped}
        proposal = base if dropped is None else _scale_marginal(model, flat, dropped)
        log_weights, k_hat = smoothed_log_weights(log_likelihood_draws(variant, used) - proposal)
        method = "psis"
        refitted = None
        limit = pareto_k_limit(log_weights.size)  # 0.67 for a table's 1000 draws
        if k_hat > limit and refit is not None:
            refitted, method = refit(variant), "refit"
        for name, values in headline.items():
            entry = result[name]
            low = high = ratio = None  # unreliable: no interval (JSON null)
            extra = {}
            if refitted is not None:
                low, high = _interval(refitted.headline[name].reshape(-1))
                extra = {"refit": refitted.record(name)}
            elif k_hat <= limit:
                low, high = weighted_interval(values, log_weights)
            else:
                method = "unreliable"
            width = widths[name]
            if low is not None and width > 0:
                ratio = (high - low) / width
            entry["without"][assumption.name] = {
                "lo95": low,
                "hi95": high,
                "ratio": ratio,
                "pareto_k": k_hat,
                "method": method,
                "words": assumption.words,
                **extra,
            }
    return result
