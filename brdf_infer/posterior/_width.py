"""What carries the width of each headline interval: the data, the prior, or an assumption of
the model, each shown as the interval under the alternative.

For each headline quantity (TIS at the scene's incidence angles and at 70°, π·BRDF0) a run
reports its 95 % interval, with the Monte Carlo standard error of each end, and

* **without each assumption** the model makes — the per-series calibration, the
  sample-to-sample effect, the angle errors, the uncertainty of Eq. (8)'s out-of-plane width
  (Δφ then fixed at the article's) — the interval the same data would give under that
  alternative, with its ends' Monte Carlo errors, and the data's judgement of the
  alternative: Δelpd = elpd_loo(alternative) − elpd_loo(run) with its standard error (PSIS-LOO
  of both on the same rows; negative: the data prefer the run's model). Where the alternative's
  interval is narrower, the assumption's **variance share** 1 − (width without / width)² is
  stated with its Monte Carlo error: independent sources of scatter add in quadrature, so this
  is the part of the interval's variance the assumption carries (0 to 1, and the shares of
  several assumptions need not add to 1: the sources also shift the median and the other
  sources' estimates). Where the alternative's interval is wider no share is stated: the
  alternative is a different, here worse-fitting or less constrained, model, not a part of the
  run's width (on the bundled data the angle errors: without them the learned repeatability
  grows to absorb the 75–80° scatter).

  The run's draws are reweighted to each alternative by Pareto-smoothed importance sampling
  (Vehtari et al. 2024, "Pareto smoothed importance sampling", JMLR 25, 72): the weight of a
  draw θ is p_alt(y | θ) p_alt(θ) / p(y | θ) p(θ) — the likelihoods' ratio, and the priors'
  where the alternative changes one (the out-of-plane width's factor leaves it, the physical
  prior's energy factor then taken at the article's Δφ) — and the Pareto k̂ of the weights says
  whether that is reliable. Where k̂ > :func:`~brdf_infer.verdict.pareto_k_limit` of the draws
  (0.7 from 2200 draws, 0.67 at a table's 1000) the alternative is sampled anew (``refit``)
  instead by the one refitter (:func:`brdf_infer.posterior._refit.refit`, 2 × 500 draws):
  importance sampling from a Student-t fitted to the run's draws, else the run's own sampler
  through its compiled program, a NUTS refit held to the refitter's convergence rule (no
  divergence, R-hat ≤ 1.01; a refused refit leaves the alternative unreliable). An end q of a 95 %
  interval from an effective sample size n has standard error ≈ the half-distance between the
  quantiles at 0.025 ± √(0.025 · 0.975 / n) (:func:`quantile_se`; n: Kish's ESS of the
  weights, or the draws' ESS at that quantile), so a width ratio from n ≈ 1000 has a relative
  error of about 0.03. Without the sample effect its scale τ no longer enters the likelihood,
  and the draws' τ, concentrated where the run's data put it, would make the weights
  p_alt(y | θ) / p(y | θ, τ) needlessly variable (k̂ ≈ 1.1 on the bundled data); the weight of
  θ is taken against the run's likelihood with τ integrated out over its prior instead,
  p_alt(y | θ) / ∫ p(y | θ, τ) p(τ) dτ (the marginal of the run's posterior in θ is then the
  proposal), by Gauss–Legendre quadrature in ln τ over the central 99 % of the run's τ draws
  widened fourfold each side (:data:`TAU_NODES`), and below that range the likelihood at its
  lower end times the prior's mass there (to O(τ²): τ enters the covariance squared).
* **the prior predictive** interval of the same quantity (draws of the physical prior,
  :func:`brdf_infer.posterior.prior_draws`) and the prior's probability of a value above 1.

Latent angle errors (``angle_method = "latent"``) are sampled, not marginalised; there the
alternatives are not computed (the reason is recorded).
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.special import logsumexp

from brdf_infer._internal import arviz as az
from brdf_infer._internal.stored_programs import StoredFunction, register_tree_types
from brdf_infer.model import ModelFamily, energy_log_factor
from brdf_infer.model.params import DPHI_NAME, HemisphereConstants, Params
from brdf_infer.model.priors import Prior
from brdf_infer.posterior._bands import draws_physical, tis_curve_draws
from brdf_infer.posterior._likelihood import noise_prior
from brdf_infer.posterior._loo import elpd_difference, psis_loo
from brdf_infer.posterior._model import DPHI_SITE, PosteriorModel, build_posterior_model
from brdf_infer.posterior._power_scaling import log_likelihood_draws, sample_scale_likelihoods
from brdf_infer.posterior._results import loo_terms
from brdf_infer.scene import Scene
from brdf_infer.tables.measurements import Measurements
from brdf_infer.verdict import pareto_k_limit

HEADLINE_TIS_DEG = 70.0  # the article's TIS angle (Sec. 7)
TAU_NODES = 24  # Gauss–Legendre nodes in ln τ (module docstring)
LEVEL = (0.025, 0.975)  # the ends of a 95 % interval


def _errors(**changes: Any) -> Callable[[Scene], Scene]:
    """The scene with these ``[errors]`` keys changed."""
    return lambda scene: dataclasses.replace(
        scene, errors=dataclasses.replace(scene.errors, **changes)
    )


def _article_width(scene: Scene) -> Scene:
    """The scene with Eq. (8)'s out-of-plane width fixed at its constants' (the article's)."""
    priors = {**scene.priors, DPHI_NAME: Prior("fixed", value=0.0)}
    return dataclasses.replace(scene, priors=priors)


@dataclass(frozen=True)
class Assumption:
    """One assumption of the model, and the scene without it.

    Attributes:
        name: its key in the ``"width"`` record.
        words: the assumption in words.
        applies: whether a scene makes it.
        remove: the scene without it (the alternative).
        unused_sites: sampled sites the alternative no longer has.
    """

    name: str
    words: str
    applies: Callable[[Scene], bool]
    remove: Callable[[Scene], Scene]
    unused_sites: tuple[str, ...] = ()


ASSUMPTIONS = (
    Assumption(  # a zero scale, not calibration = "none": the run's programs serve it
        "calibration",
        "the calibration",
        lambda scene: scene.errors.calibration_sd > 0,
        _errors(calibration_rel=0.0),
    ),
    Assumption(
        "sample_effect",
        "the sample-to-sample effect",
        lambda scene: scene.errors.sample_effects,
        _errors(hierarchical=False),
        ("sample_sd",),
    ),
    Assumption(  # zero scales, not propagate_angles = False: the run's program serves it
        "angle_errors",
        "the angle errors",
        lambda scene: scene.errors.angles_on,
        _errors(rotation_deg=0.0, camera_deg=0.0),
    ),
    Assumption(
        "out_of_plane",
        "the out-of-plane width's uncertainty",
        lambda scene: scene.dphi_free,
        _article_width,
        (DPHI_SITE, DPHI_NAME),
    ),
)


@dataclass(frozen=True)
class Refitted:
    """An alternative's headline quantities from a new posterior of its own (a refit).

    Attributes:
        headline: every draw of each headline quantity, (chains, draws) [fraction].
        settings: the refit's ``chains``, ``draws`` (per chain) and ``sampler``
            (``importance`` with its ``pareto_k`` and ``ess``, ``laplace``, or ``nuts`` with
            its ``warmup``).
        sites: its draws, (chains, draws, ...), for its leave-one-out terms.
    """

    headline: dict[str, np.ndarray]
    settings: dict[str, int | str]
    sites: dict[str, np.ndarray]

    def mcse(self, name: str) -> tuple[float, float]:
        """The Monte Carlo standard errors of ``name``'s 95 % ends (ArviZ's quantile MCSE,
        from the effective sample size at each quantile)."""
        values = self.headline[name]
        return tuple(float(az.mcse(values, method="quantile", prob=p)) for p in LEVEL)


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
    if len(tis_angles):
        angles = np.asarray(sorted(set(float(a) for a in tis_angles)))
        flat = {k: np.asarray(v).reshape(-1) for k, v in physical.items()}
        if member.log_tis_draws is not None:
            tis = np.exp(np.asarray(member.log_tis_draws(angles, flat)))
        else:  # a 2-D quadrature per TIS (≈ 1 ms): the callers pass few draws
            tis = tis_curve_draws(member, flat, angles)
        values.update({tis_quantity(a): tis[:, k] for k, a in enumerate(angles)})
    if member.paper_parameters:
        values["pi_brdf0"] = np.pi * np.asarray(physical["brdf0"]).reshape(-1)
    return values


def headline_angles(headline: dict[str, np.ndarray]) -> list[float]:
    """The TIS angles [deg] among headline quantities' names (``tis_70deg`` → 70)."""
    return [float(name[4:-3]) for name in headline if name.startswith("tis_")]


def weighted_quantile(values: np.ndarray, log_weights: np.ndarray, probs) -> np.ndarray:
    """Quantiles of ``values`` under normalised ``exp(log_weights)`` (the weighted empirical
    CDF, interpolated at mid-points)."""
    order = np.argsort(values)
    weights = np.exp(log_weights[order] - np.max(log_weights))
    cdf = (np.cumsum(weights) - 0.5 * weights) / np.sum(weights)
    return np.interp(probs, cdf, values[order])


def weighted_interval(values: np.ndarray, log_weights: np.ndarray) -> tuple[float, float]:
    """The central 95 % interval of ``values`` under normalised ``exp(log_weights)``."""
    low, high = weighted_quantile(values, log_weights, LEVEL)
    return float(low), float(high)


def quantile_se(values: np.ndarray, prob: float, ess: float, log_weights=None) -> float:
    """The Monte Carlo standard error of the ``prob`` quantile of ``values`` (weighted by
    ``log_weights`` where given) from ``ess`` effective draws: half the distance between the
    quantiles at prob ± √(prob (1 − prob) / ess), the order-statistic interval of a quantile."""
    step = np.sqrt(prob * (1.0 - prob) / max(ess, 1.0))
    probs = np.clip([prob - step, prob + step], 0.0, 1.0)
    if log_weights is None:
        low, high = np.quantile(values, probs)
    else:
        low, high = weighted_quantile(values, log_weights, probs)
    return float(high - low) / 2.0


def kish_ess(log_weights: np.ndarray) -> float:
    """Kish's effective sample size of importance weights, (Σw)²/Σw²."""
    weights = np.exp(log_weights - np.max(log_weights))
    return float(weights.sum() ** 2 / np.sum(weights**2))


def _interval(values: np.ndarray) -> tuple[float, float]:
    low, high = np.quantile(values, LEVEL)
    return float(low), float(high)


def smoothed_log_weights(log_ratio: np.ndarray) -> tuple[np.ndarray, float]:
    """Pareto-smoothed log importance weights of draws and their k̂ (ArviZ ``psislw``); equal
    ratios (an alternative of the same likelihood, e.g. the out-of-plane width on in-plane
    rows) are equal weights with k̂ 0 (the Pareto fit to a constant tail is undefined: ∞)."""
    log_ratio = np.asarray(log_ratio, float)
    if np.ptp(log_ratio) <= 1e-12 * max(1.0, float(np.max(np.abs(log_ratio)))):
        return np.full(log_ratio.shape, -np.log(log_ratio.size)), 0.0
    with warnings.catch_warnings():  # ArviZ warns on k̂ > 0.7; the caller reports it
        warnings.simplefilter("ignore")
        log_weights, k_hat = az.psislw(np.asarray(log_ratio, float) - np.max(log_ratio))
    return np.asarray(log_weights), float(k_hat)


def _scale_marginal(model: PosteriorModel, flat: dict[str, np.ndarray], site: str) -> np.ndarray:
    """ln ∫ p(y | θ, τ) p(τ) dτ of every draw's θ, τ the learned scale ``site`` under its
    prior (module docstring)."""
    draws = np.asarray(flat[site], float)
    prior = noise_prior(model.errors, site)
    # the draws' central 99 %, widened fourfold each side: the extreme draws of a half-normal
    # reach 1e-6, and nodes spread to there left too few where the mass is (0.008 in ln)
    low = np.log(max(np.quantile(draws, 0.005), 1e-12) / 4.0)
    high = max(np.log(max(np.quantile(draws, 0.995), 1e-12) * 4.0), low + np.log(16.0))
    x, w = np.polynomial.legendre.leggauss(TAU_NODES)
    log_tau = low + 0.5 * (high - low) * (x + 1.0)
    tau = np.exp(log_tau)
    # p(τ) dτ = p(τ) τ d ln τ
    log_prior = np.asarray(prior.log_prob(tau)) + log_tau
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
    # covariance as τ²), times the prior's mass below, its CDF at e^low
    below = terms[:, -1]
    return np.logaddexp(inside, below + np.log(float(prior.cdf(floor))))


def variant_model(
    model: PosteriorModel, measurements: Measurements, assumption: Assumption
) -> PosteriorModel:
    """``model`` with ``assumption`` removed from its scene (its family the new scene's: the
    same family, without the out-of-plane width's parameter where that is removed)."""
    scene = assumption.remove(model.scene)
    member = scene.family(model.family.name) if model.family.paper_parameters else model.family
    return build_posterior_model(scene, measurements, member)


register_tree_types((Params, HemisphereConstants))
# the energy factor of many draws, one compiled program per shape, loaded on a warm run
# (traced eagerly, its operations took ≈ 1 s of every run's width record)
_ENERGY_FACTOR = StoredFunction(energy_log_factor, ("energy_log_factor",))


def _prior_ratio(model: PosteriorModel, variant: PosteriorModel, flat: dict) -> np.ndarray:
    """ln p_alt(θ) − ln p(θ) of every draw where the alternative changes the prior: the
    physical prior's energy factor at the alternative's Δφ against the draw's (the factor
    ``dphi_scale`` itself leaves both sides as the auxiliary of the alternative); 0 else."""
    if variant.family.dphi_free == model.family.dphi_free:
        return np.zeros(len(next(iter(flat.values()))))
    params = Params(*(np.asarray(flat[name]) for name in Params._fields))
    ours = _ENERGY_FACTOR(params, _as_arrays(model.family.constants_of(flat)))
    theirs = _ENERGY_FACTOR(params, _as_arrays(variant.family.constants_of(flat)))
    return np.asarray(theirs) - np.asarray(ours)


def _as_arrays(constants: HemisphereConstants) -> HemisphereConstants:
    """Eq. (8)'s constants as float64 arrays (a Python float has no dtype for a program)."""
    return HemisphereConstants(*(np.asarray(value, float) for value in constants))


def variant_elpd(
    variant: PosteriorModel,
    sites: dict[str, np.ndarray],
    run_elpd_i: np.ndarray,
    log_weights: np.ndarray | None = None,
    reff: float = 1.0,
) -> tuple[float, float]:
    """Δelpd = elpd_loo(alternative) − elpd_loo(run) and its standard error √(n Var Δᵢ), from
    the alternative's leave-one-out terms at ``sites`` (chains, draws, …): its own draws
    (a refit; PSIS-LOO), or the run's reweighted by ``log_weights`` (flattened draws): each
    row's ratio wₛ / p_alt(yᵢ | y₋ᵢ, θₛ) Pareto-smoothed with ``reff`` (the run's own), elpdᵢ
    = ln Σ r̃ₛ p / Σ r̃ₛ."""
    log_lik, cdf = loo_terms(variant, sites)
    if log_weights is None:
        elpd_i = psis_loo(log_lik, cdf, reff).elpd_i
    else:
        terms = np.reshape(np.asarray(log_lik, float), (-1, log_lik.shape[-1])).T  # rows, draws
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ratios, _ = az.psislw(log_weights[None, :] - terms, reff)
        elpd_i = logsumexp(ratios + terms, axis=1) - logsumexp(ratios, axis=1)
    return elpd_difference(elpd_i, run_elpd_i)


def by_chains(values: np.ndarray, chains: int) -> np.ndarray:
    """Flattened draws as (chains, draws) for ArviZ's ESS (one chain where they do not
    divide evenly, e.g. draws evenly spaced over all chains)."""
    values = np.asarray(values)
    return np.reshape(values, (chains if values.size % chains == 0 else 1, -1))


def _intervals(
    headline: dict[str, np.ndarray], prior_headline: dict[str, np.ndarray], chains: int
) -> dict[str, Any]:
    """Each quantity's 95 % interval with its ends' Monte Carlo errors (the draws' ESS at
    each quantile, ``chains`` chains) and its prior predictive interval (``without`` left
    empty)."""
    result: dict[str, Any] = {}
    for name, values in headline.items():
        low, high = _interval(values)
        by_chain = by_chains(values, chains)
        prior = prior_headline[name]
        prior_low, prior_high = _interval(prior)
        result[name] = {
            "lo95": low,
            "hi95": high,
            "mcse_lo95": float(az.mcse(by_chain, method="quantile", prob=LEVEL[0])),
            "mcse_hi95": float(az.mcse(by_chain, method="quantile", prob=LEVEL[1])),
            "prior": {
                "lo95": prior_low,
                "hi95": prior_high,
                "p_above_1": float(np.mean(prior > 1.0)),
            },
            "without": {},
        }
    return result


def variance_share(ratio: float | None, relative_error: float) -> tuple[float | None, float | None]:
    """1 − ratio² (the part of the interval's variance an assumption carries, sources adding
    in quadrature) and its Monte Carlo error 2·ratio²·(the ratio's relative error); None, None
    where the alternative's interval is wider (no share of the run's width)."""
    if ratio is None or ratio > 1.0:
        return None, None
    return 1.0 - ratio**2, 2.0 * ratio**2 * relative_error


def width_attribution(
    model: PosteriorModel,
    measurements: Measurements,
    sites: dict[str, np.ndarray],
    headline: dict[str, np.ndarray],
    prior_headline: dict[str, np.ndarray],
    refit: Callable[[PosteriorModel], Refitted | None] | None = None,
    log_likelihood: np.ndarray | None = None,
    run_headline: dict[str, np.ndarray] | None = None,
    run_elpd_i: np.ndarray | None = None,
    reff: float = 1.0,
) -> dict[str, Any]:
    """The ``"width"`` record of a run (module docstring).

    Args:
        model: the run's posterior model.
        measurements: its rows.
        sites: its draws, (chains, draws, ...).
        headline: every draw (flattened) of each headline quantity (:func:`headline_draws`).
        prior_headline: the same quantities over draws of the physical prior.
        refit: an alternative's headline draws from a new posterior (:class:`Refitted`) where
            the weights' k̂ exceeds their limit (None: reported with k̂, no interval).
        log_likelihood: the run's joint ln p(y | θ) of every draw (None: computed here).
        run_headline: where ``sites`` are a thinned set of the draws (a large table), the
            headline over all: the run's intervals; each ratio is over the thinned width.
        run_elpd_i: the run's PSIS-LOO terms from the same draws (None: no Δelpd).
        reff: the relative efficiency the run's PSIS-LOO smoothed with (the alternatives'
            terms are smoothed alike, so that an alternative of the same likelihood has
            Δelpd 0).

    Returns:
        ``{QUANTITY: {"lo95", "hi95", "mcse_lo95", "mcse_hi95", "prior": {"lo95", "hi95",
        "p_above_1"}, "without": {ASSUMPTION: {"lo95", "hi95", "mcse_lo95", "mcse_hi95",
        "ratio", "variance_share", "variance_share_mcse", "delta_elpd", "delta_elpd_se",
        "pareto_k", "method", "words"}}}}`` (an unreliable alternative's interval, ratio and
        share None; a wider one's share None; a refitted one's also ``"refit"``: its settings)
        and, where no alternative was computed, ``"without_note"``.
    """
    chains = np.shape(next(iter(sites.values())))[0]  # thinned draws keep every chain
    result = _intervals(headline if run_headline is None else run_headline, prior_headline, chains)
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
        if not assumption.applies(model.scene):
            continue
        variant = variant_model(model, measurements, assumption)
        found = _alternative(model, variant, assumption, flat, base, headline, refit)
        elpd = (None, None)
        if run_elpd_i is not None and found.usable:
            used = {k: v for k, v in sites.items() if k not in assumption.unused_sites}
            elpd = (
                variant_elpd(variant, found.sites, run_elpd_i, reff=reff)
                if found.refitted is not None
                else variant_elpd(variant, used, run_elpd_i, found.log_weights, reff)
            )
        for name, entry in result.items():
            own = _interval(headline[name])  # the ratio over the same draws' width
            found_entry = found.entry(name, entry, own, assumption.words, elpd)
            entry["without"][assumption.name] = found_entry
    return result


@dataclass
class _Found:
    """An alternative's draws: reweighted (``log_weights`` over the run's flattened draws, of
    Pareto ``k_hat``) or refitted; ``values``: its headline draws."""

    values: dict[str, np.ndarray]
    log_weights: np.ndarray | None
    k_hat: float
    method: str
    refitted: Refitted | None = None

    @property
    def usable(self) -> bool:
        return self.method != "unreliable"

    @property
    def sites(self) -> dict[str, np.ndarray]:
        return {} if self.refitted is None else self.refitted.sites

    def entry(
        self, name: str, run: dict[str, Any], own: tuple[float, float], words: str, elpd
    ) -> dict[str, Any]:
        """The ``without`` entry of quantity ``name`` (``run``: the run's interval record;
        ``own``: the run's interval over the draws reweighted, whose width the ratio is
        over: on a thinned table the two share their Monte Carlo error)."""
        low = high = ratio = mcse_low = mcse_high = None
        extra = {}
        if self.refitted is not None:
            low, high = _interval(self.refitted.headline[name].reshape(-1))
            mcse_low, mcse_high = self.refitted.mcse(name)
            extra = {"refit": self.refitted.settings}
        elif self.usable:
            values = self.values[name]
            # equal weights (an alternative of the same likelihood): the run's own quantiles,
            # so that a quantity the assumption does not touch keeps its interval exactly
            weights = None if np.ptp(self.log_weights) == 0.0 else self.log_weights
            low, high = _interval(values) if weights is None else weighted_interval(values, weights)
            ess = kish_ess(self.log_weights)
            mcse_low, mcse_high = (quantile_se(values, p, ess, weights) for p in LEVEL)
        share = share_error = None
        width = own[1] - own[0]
        if low is not None and width > 0:
            ratio = (high - low) / width
            relative = np.hypot(
                np.hypot(mcse_low, mcse_high) / max(high - low, 1e-300),
                np.hypot(run["mcse_lo95"], run["mcse_hi95"]) / width,
            )
            share, share_error = variance_share(ratio, float(relative))
        return {
            "lo95": low,
            "hi95": high,
            "mcse_lo95": mcse_low,
            "mcse_hi95": mcse_high,
            "ratio": ratio,
            "variance_share": share,
            "variance_share_mcse": share_error,
            "delta_elpd": elpd[0],
            "delta_elpd_se": elpd[1],
            "pareto_k": self.k_hat,
            "method": self.method,
            "words": words,
            **extra,
        }


def _alternative(model, variant, assumption, flat, base, headline, refit) -> _Found:
    """The alternative's draws: the run's reweighted where k̂ allows, else a refit (or
    unreliable where none is allowed)."""
    unused = set(assumption.unused_sites)
    used = {k: v for k, v in flat.items() if k not in unused}
    marginal = "sample_sd" in unused and "sample_sd" in flat  # else τ is stated: no integral
    proposal = _scale_marginal(model, flat, "sample_sd") if marginal else base
    log_ratio = log_likelihood_draws(variant, used) - proposal
    log_ratio = log_ratio + _prior_ratio(model, variant, flat)
    log_weights, k_hat = smoothed_log_weights(log_ratio)
    values = headline
    if variant.family.parameters != model.family.parameters:  # Δφ fixed: TIS at the article's
        products = variant.products
        values = headline_draws(products, draws_physical(flat, products), headline_angles(headline))
    limit = pareto_k_limit(log_weights.size)  # 0.67 for a table's 1000 draws
    if k_hat <= limit:
        return _Found(values, log_weights, k_hat, "psis")
    refitted = refit(variant) if refit is not None else None
    if refitted is not None:
        return _Found(values, None, k_hat, "refit", refitted)
    return _Found(values, None, k_hat, "unreliable")
