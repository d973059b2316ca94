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

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.linalg import solve_triangular
from jax.scipy.stats import norm
from scipy import stats

from brdf_infer._arviz import az


def loo_conditionals(y, mean, factor, diagonal) -> tuple[jnp.ndarray, jnp.ndarray]:
    """(mean, sd) of yᵢ | y₋ᵢ for every row, one draw (vmap for many).

    Args:
        y: observed values (n,).
        mean: μ (n,).
        factor: W (n, k).
        diagonal: D (n,), > 0.
    """
    residual = y - mean
    inverse_diagonal = 1.0 / diagonal
    capacitance = jnp.eye(factor.shape[1]) + (factor.T * inverse_diagonal) @ factor
    cholesky = jnp.linalg.cholesky(capacitance)
    scaled = solve_triangular(cholesky, factor.T * inverse_diagonal, lower=True)  # k × n
    precision_residual = inverse_diagonal * residual - scaled.T @ (scaled @ residual)
    precision_diagonal = inverse_diagonal - jnp.sum(scaled**2, axis=0)
    return y - precision_residual / precision_diagonal, 1.0 / jnp.sqrt(precision_diagonal)


@jax.jit
def pointwise_loo_terms(y, means, factors, diagonals) -> tuple[jnp.ndarray, jnp.ndarray]:
    """(log p(yᵢ | y₋ᵢ, θ_s), P(ỹᵢ ≤ yᵢ | y₋ᵢ, θ_s)) for every draw s and row i."""

    def one(mean, factor, diagonal):
        conditional_mean, conditional_sd = loo_conditionals(y, mean, factor, diagonal)
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
