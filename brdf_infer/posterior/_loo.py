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

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.stats import norm
from scipy import stats

from brdf_infer._arviz import az
from brdf_infer.posterior._lowrank import leave_one_out_conditionals


@partial(jax.jit, static_argnames="disjoint")
def pointwise_loo_terms(
    y, means, factors, diagonals, disjoint: int = 0
) -> tuple[jnp.ndarray, jnp.ndarray]:
    """(log p(yᵢ | y₋ᵢ, θ_s), P(ỹᵢ ≤ yᵢ | y₋ᵢ, θ_s)) for every draw s and row i
    (``disjoint``: leading columns of W with non-overlapping rows, see :mod:`._lowrank`)."""

    def one(mean, factor, diagonal):
        conditional_mean, conditional_sd = leave_one_out_conditionals(
            y, mean, factor, diagonal, disjoint
        )
        z = (y - conditional_mean) / conditional_sd
        return norm.logpdf(y, conditional_mean, conditional_sd), norm.cdf(z)

    return jax.vmap(one)(means, factors, diagonals)


def loo_pit(log_likelihood: np.ndarray, cdf: np.ndarray) -> np.ndarray:
    """LOO-PIT of each row: Σ_s w_si P(ỹᵢ ≤ yᵢ | θ_s) with PSIS weights from log p(yᵢ|y₋ᵢ,θ_s).

    Args:
        log_likelihood: (draws, rows) pointwise leave-one-out log likelihood.
        cdf: (draws, rows) conditional predictive CDF at the observation.
    """
    log_weights, _ = az.psislw(-np.asarray(log_likelihood).T)  # (rows, draws): draws last
    weights = np.exp(log_weights - np.max(log_weights, axis=1, keepdims=True))
    weights /= weights.sum(axis=1, keepdims=True)
    return np.clip(np.sum(weights * np.asarray(cdf).T, axis=1), 0.0, 1.0)


def uniformity_p_value(values: np.ndarray) -> float:
    """Kolmogorov–Smirnov p-value of ``values`` against U(0, 1)."""
    return float(stats.kstest(np.asarray(values), "uniform").pvalue)
