"""Leave-one-out predictive of each row for a low-rank-plus-diagonal normal likelihood.

With correlated rows, the pointwise log likelihood that PSIS-LOO needs is that of the
leave-one-out conditional p(yᵢ | y₋ᵢ, θ), not of the marginal p(yᵢ | θ) (Bürkner, Gabry &
Vehtari 2021, "Efficient leave-one-out cross-validation for Bayesian non-factorized normal
and Student-t models", Comput. Stat. 36, 1243). For y ~ N(μ, Σ) with precision Q = Σ⁻¹,

    yᵢ | y₋ᵢ ~ N(yᵢ − (Q(y − μ))ᵢ / Qᵢᵢ,  1/Qᵢᵢ).

Here Σ = D + W Wᵀ, so Q follows from the Woodbury identity with one k×k Cholesky
(k = columns of W): Q = D⁻¹ − D⁻¹ W C⁻¹ Wᵀ D⁻¹, C = I + Wᵀ D⁻¹ W. For independent rows
(W = 0) this is the ordinary pointwise normal.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.stats import norm
from scipy import stats
from scipy.special import logsumexp

from brdf_infer._internal import arviz as az
from brdf_infer._internal.lowrank import leave_one_out_conditionals
from brdf_infer.verdict import PARETO_K_LIMIT, pareto_k_limit


@partial(jax.jit, static_argnames="disjoint")
def pointwise_loo_terms(
    y, means, factors, diagonals, disjoint: int = 0
) -> tuple[jnp.ndarray, jnp.ndarray]:
    """(log p(yᵢ | y₋ᵢ, θ_s), P(ỹᵢ ≤ yᵢ | y₋ᵢ, θ_s)) for every draw s and row i
    (``disjoint``: leading columns of W with non-overlapping rows, see ``_internal.lowrank``)."""

    def one(mean, factor, diagonal):
        conditional_mean, conditional_sd = leave_one_out_conditionals(
            y, mean, factor, diagonal, disjoint
        )
        z = (y - conditional_mean) / conditional_sd
        return norm.logpdf(y, conditional_mean, conditional_sd), norm.cdf(z)

    return jax.vmap(one)(means, factors, diagonals)


def loo_pit(log_likelihood: np.ndarray, cdf: np.ndarray, reff: float = 1.0) -> np.ndarray:
    """LOO-PIT of each row: Σ_s w_si P(ỹᵢ ≤ yᵢ | θ_s) with PSIS weights from log p(yᵢ|y₋ᵢ,θ_s).

    Args:
        log_likelihood: (draws, rows) pointwise leave-one-out log likelihood.
        cdf: (draws, rows) conditional predictive CDF at the observation.
        reff: the draws' relative efficiency, as for PSIS-LOO.
    """
    log_weights, _ = az.psislw(-np.asarray(log_likelihood).T, reff)  # (rows, draws)
    return weighted_pit(log_weights, np.asarray(cdf).T)


def weighted_pit(log_weights: np.ndarray, cdf: np.ndarray) -> np.ndarray:
    """Σ_s w_si P(ỹᵢ ≤ yᵢ | θ_s) from (rows, draws) log weights and conditional CDFs."""
    weights = np.exp(log_weights - np.max(log_weights, axis=1, keepdims=True))
    weights /= weights.sum(axis=1, keepdims=True)
    return np.clip(np.sum(weights * cdf, axis=1), 0.0, 1.0)


def uniformity_p_value(values: np.ndarray) -> float:
    """Kolmogorov–Smirnov p-value of ``values`` against U(0, 1)."""
    return float(stats.kstest(np.asarray(values), "uniform").pvalue)


ROWS_PER_CHUNK = 2048  # rows smoothed at once: 2048 rows × 4000 draws × 8 B = 64 MiB a term


class ExactTerm(NamedTuple):
    """A row's leave-one-out term from a refit without it (:mod:`._loo_refit`).

    Attributes:
        elpd: ln p(yᵢ | y₋ᵢ).
        pit: P(ỹᵢ ≤ yᵢ | y₋ᵢ), the row's LOO-PIT.
        mcse: the Monte Carlo standard error of ``elpd`` (:func:`log_mean_mcse`).
    """

    elpd: float
    pit: float
    mcse: float


def log_mean_mcse(log_terms: np.ndarray) -> float:
    """The Monte Carlo standard error of ln mean_s p_s from MCMC draws of ln p_s, (chains,
    draws): by the delta method, sd(p) / (mean(p) √ESS), ESS of p by ArviZ (autocorrelation
    across chains), p scaled by its largest value (the ratio is scale-free)."""
    values = np.exp(np.asarray(log_terms, float) - np.max(log_terms))
    if np.ptp(values) == 0:
        return 0.0
    ess = float(az.ess(values[None] if values.ndim == 1 else values))
    return float(np.std(values) / (np.mean(values) * np.sqrt(ess)))


def psis_mcse(log_weights: np.ndarray, log_terms: np.ndarray, reff: float) -> np.ndarray:
    """Every row's Monte Carlo standard error of a PSIS-LOO term ln Σ_s w̃_s p_s, by the delta
    method (Vehtari, Gelman & Gabry 2017, Sec. 2.2, and the ``loo`` package's
    ``mcse_elpd_loo``): Var ≈ Σ_s w̃_s² (p_s − E)² / r_eff, E = Σ_s w̃_s p_s, se = √Var / E,
    w̃ the normalised smoothed weights.

    Args:
        log_weights: (rows, draws) smoothed log weights (:func:`az.psislw`).
        log_terms: (rows, draws) ln p(yᵢ | y₋ᵢ, θ_s).
        reff: the draws' relative efficiency.
    """
    weights = np.exp(log_weights - np.max(log_weights, axis=1, keepdims=True))
    weights /= weights.sum(axis=1, keepdims=True)
    values = np.exp(log_terms - np.max(log_terms, axis=1, keepdims=True))  # scale-free ratio
    expected = np.sum(weights * values, axis=1)
    variance = np.sum(weights**2 * (values - expected[:, None]) ** 2, axis=1) / reff
    return np.sqrt(variance) / expected


@dataclass(frozen=True)
class LeaveOneOut:
    """PSIS-LOO of a run (Vehtari, Gelman & Gabry 2017, Stat. Comput. 27, 1413) and the
    LOO-PIT of every row.

    Attributes:
        elpd_loo: Σᵢ ln p(yᵢ | y₋ᵢ) estimated by Pareto-smoothed importance sampling.
        se: its standard error, √(n Var(elpdᵢ)).
        p_loo: the effective number of parameters, lppd − elpd_loo.
        pareto_k: the Pareto shape k̂ of every row's importance weights, (rows,).
        pit: the LOO-PIT of every row, (rows,) (:func:`loo_pit`); None where no conditional
            CDF was given (a study's ranking reads the elpd only).
        elpd_i: every row's term of ``elpd_loo``, (rows,).
        lppd_i: every row's ln mean_s p(yᵢ | y₋ᵢ, θ_s) over the draws, (rows,).
        limit: the k̂ above which a row's estimate is unreliable with this many draws
            (:func:`~brdf_infer.verdict.pareto_k_limit`: 0.7 from 2200 draws, 0.67 at 1000).
        mcse_i: every row's Monte Carlo standard error of ``elpd_i`` (:func:`psis_loo`; a
            refitted row's from its refit), (rows,); None where not estimated.
    """

    elpd_loo: float
    se: float
    p_loo: float
    pareto_k: np.ndarray
    pit: np.ndarray | None
    elpd_i: np.ndarray
    lppd_i: np.ndarray
    limit: float = PARETO_K_LIMIT
    mcse_i: np.ndarray | None = None

    def with_exact(self, exact: dict[int, ExactTerm]) -> LeaveOneOut:
        """These estimates with the rows of ``exact`` (row → exact ln p(yᵢ | y₋ᵢ), LOO-PIT and
        Monte Carlo standard error, :mod:`brdf_infer.posterior._loo_refit`) put in; ``p_loo``
        follows the new elpd (lppd − elpd_loo, the lppd unchanged), the k̂ stay the importance
        sampling's."""
        elpd_i = self.elpd_i.copy()
        pit = None if self.pit is None else self.pit.copy()
        mcse_i = None if self.mcse_i is None else self.mcse_i.copy()
        for row, term in exact.items():
            elpd_i[row] = term.elpd
            if pit is not None:
                pit[row] = term.pit
            if mcse_i is not None:
                mcse_i[row] = term.mcse
        return LeaveOneOut(
            elpd_loo=float(elpd_i.sum()),
            se=standard_error(elpd_i),
            p_loo=float(self.lppd_i.sum() - elpd_i.sum()),
            pareto_k=self.pareto_k,
            pit=pit,
            elpd_i=elpd_i,
            lppd_i=self.lppd_i,
            limit=self.limit,
            mcse_i=mcse_i,
        )


def relative_efficiency(posterior, thinning: int = 1) -> float:
    """The relative efficiency of a posterior's draws, the mean over its variables of the
    mean's ESS over the number of draws (1 for one chain): what ArviZ's ``loo`` passes to the
    Pareto smoothing, so it is computed over every variable of the posterior group as it is
    written. ``thinning``: the factor by which the draws PSIS-LOO reads were thinned, which
    raises their relative efficiency by up to that factor (capped at 1)."""
    chains, draws = len(posterior.chain), len(posterior.draw)
    if chains == 1:
        return 1.0
    ess = az.ess(posterior, method="mean")
    means = np.hstack([ess[name].values.ravel() for name in ess.data_vars])
    reff = float(means.mean() / (chains * draws))
    return reff if thinning == 1 else min(1.0, reff * thinning)


def psis_loo(
    log_likelihood: np.ndarray,
    cdf: np.ndarray | None,
    reff: float,
    rows_per_chunk: int = ROWS_PER_CHUNK,
) -> LeaveOneOut:
    """PSIS-LOO and LOO-PIT from the pointwise leave-one-out terms, a block of rows at a time,
    so that no more than ``rows_per_chunk`` × draws weights are held at once (the terms
    themselves may be float32: the sums are in float64).

    The same estimator as ArviZ's ``loo`` and ``loo_pit``, to rounding: one set of weights,
    smoothed with ``reff`` as both of them smooth theirs, serves the elpd and the LOO-PIT (the
    conditional CDF in place of ArviZ's predictive draws ỹ ≤ y).

    Args:
        log_likelihood: (chains, draws, rows) log p(yᵢ | y₋ᵢ, θ_s).
        cdf: (chains, draws, rows) P(ỹᵢ ≤ yᵢ | y₋ᵢ, θ_s); None: no LOO-PIT (``pit`` None).
        reff: :func:`relative_efficiency` of the draws.
    """
    rows = log_likelihood.shape[-1]
    terms = np.reshape(log_likelihood, (-1, rows))
    cdf = None if cdf is None else np.reshape(cdf, (-1, rows))
    draws = terms.shape[0]
    elpd, lppd, mcse = np.empty(rows), np.empty(rows), np.empty(rows)
    pareto_k, pit = np.empty(rows), np.empty(rows)
    for start in range(0, rows, rows_per_chunk):
        block = slice(start, start + rows_per_chunk)
        values = np.asarray(terms[:, block], float).T  # (rows, draws): draws last
        log_weights, pareto_k[block] = az.psislw(-values, reff)
        elpd[block] = logsumexp(log_weights + values, axis=1)
        lppd[block] = logsumexp(values, axis=1) - np.log(draws)
        mcse[block] = psis_mcse(log_weights, values, reff)
        if cdf is not None:
            pit[block] = weighted_pit(log_weights, np.asarray(cdf[:, block], float).T)
    return LeaveOneOut(
        elpd_loo=float(elpd.sum()),
        se=standard_error(elpd),
        p_loo=float(lppd.sum() - elpd.sum()),
        pareto_k=pareto_k,
        pit=None if cdf is None else pit,
        elpd_i=elpd,
        lppd_i=lppd,
        limit=pareto_k_limit(draws),
        mcse_i=mcse,
    )


def standard_error(elpd_i: np.ndarray) -> float:
    """The standard error of a sum of n pointwise terms, √(n Var(elpdᵢ)) (Vehtari, Gelman &
    Gabry 2017, Eq. 23): of elpd_loo, or, of the terms' differences, of Δelpd (Eq. 24)."""
    elpd_i = np.asarray(elpd_i, float)
    return float(np.sqrt(elpd_i.size * np.var(elpd_i)))


def elpd_difference(elpd_i: np.ndarray, reference_i: np.ndarray) -> tuple[float, float]:
    """Δelpd = Σᵢ (elpdᵢ − referenceᵢ) of two models' leave-one-out terms on the same rows and
    its standard error √(n Var(elpdᵢ − referenceᵢ)) (Vehtari, Gelman & Gabry 2017, Eq. 24:
    the paired estimate, not the two standard errors combined): as ArviZ's ``compare`` has
    ``elpd_diff`` and ``dse`` (there best − other)."""
    difference = np.asarray(elpd_i, float) - np.asarray(reference_i, float)
    return float(difference.sum()), standard_error(difference)


def stacking_weights(elpd_i: np.ndarray) -> np.ndarray:
    """Stacking weights of models from their leave-one-out terms, (models, rows): the w on the
    simplex that maximise Σᵢ ln Σₖ wₖ p(yᵢ | y₋ᵢ, Mₖ) (Yao, Vehtari, Simpson & Gelman 2018,
    "Using stacking to average Bayesian predictive distributions", Bayesian Anal. 13, 917),
    by SLSQP from equal weights as ArviZ's ``compare(method="stacking")``; each row's densities
    are scaled by their largest (which moves the objective by a constant and leaves its
    gradient), so that terms below ln(10⁻³⁰⁸) do not underflow to a zero density."""
    from scipy.optimize import Bounds, LinearConstraint, minimize

    terms = np.asarray(elpd_i, float).T  # (rows, models)
    density = np.exp(terms - np.max(terms, axis=1, keepdims=True))
    models = density.shape[1]

    def log_score(weights):
        return -np.sum(np.log(density @ weights))

    def gradient(weights):
        return -np.sum(density / (density @ weights)[:, None], axis=0)

    result = minimize(
        fun=log_score,
        x0=np.full(models, 1.0 / models),
        jac=gradient,
        bounds=Bounds(lb=np.zeros(models), ub=np.ones(models)),
        constraints=LinearConstraint(np.ones(models), lb=1.0, ub=1.0),
    )
    return np.asarray(result.x)


class Ranked(NamedTuple):
    """One model of a PSIS-LOO ranking (:func:`rank_models`).

    Attributes:
        name: the model.
        loo: its PSIS-LOO.
        d_elpd, dse: the best model's elpd_loo minus its own (≥ 0) and the difference's
            standard error (:func:`elpd_difference`).
        weight: its stacking weight (:func:`stacking_weights`).
    """

    name: str
    loo: LeaveOneOut
    d_elpd: float
    dse: float
    weight: float


def rank_models(loos: dict[str, LeaveOneOut]) -> list[Ranked]:
    """Models by their PSIS-LOO on the same rows, best (largest elpd_loo) first, each with its
    difference to the best and the stacking weights: ArviZ's ``compare(method="stacking")``
    of the same terms (``elpd_diff``, ``dse``, ``weight``)."""
    order = sorted(loos, key=lambda name: loos[name].elpd_loo, reverse=True)
    weights = stacking_weights(np.stack([loos[name].elpd_i for name in order]))
    best = loos[order[0]].elpd_i
    return [
        Ranked(name, loos[name], *elpd_difference(best, loos[name].elpd_i), float(weight))
        for name, weight in zip(order, weights, strict=True)
    ]
