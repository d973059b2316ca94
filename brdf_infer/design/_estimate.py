"""Expected posterior spread after new rows, from the run's own draws (the numerical core).

The predictive of a new row. Under the generative error model (:mod:`brdf_infer.model.error_model`)
the measured rows are y = μ(θ) + W z + e with z ~ N(0, I) the shared effects (per sample,
per calibration group, per rotation setting), e ~ N(0, D) and Cov(y) = D + W Wᵀ. Given the
measured residual r = y − μ and a draw θ, the shared effects are z | y, θ ~ N(m_z, C⁻¹) with

    C = I + Wᵀ D⁻¹ W,   m_z = C⁻¹ Wᵀ D⁻¹ r        (Woodbury; one q × q Cholesky).

A new row c of the same series and sample loads on the same effects, y_c = μ_c + w_c·z + e_c
(w_c: τ on its sample's column, σ_cal on its calibration group's, σ_rot g_rot on its rotation
setting's where that (series, sample, θi) was measured before; a new setting's rotation error
and the row's camera position are its own, so they enter its own variance d_c with the value
noise and the repeatability). So a set of new rows has, per draw, the conditional predictive

    y_new | y, θ ~ N(μ_new + W_new m_z,  diag(d_new) + B Bᵀ),   B = W_new L_C⁻ᵀ,

which is exactly the new rows' conditional given the measured rows, not an independent draw:
a new row continuing series II's session inherits what the data say about series II's
calibration factor. A row of a new session loads on its sample's column only; its session's
calibration factor is a further column of B, σ_cal for every row of that session, which no
measured row loads on (:func:`brdf_infer.design.predictive`).

The expected posterior variance. For draws θ_s (s = 1…S, an evenly thinned posterior) and a
set of settings x, simulate J outcomes y_j ~ p(y | θ_{s_j}, x, D) (s_j evenly spaced, common
random numbers for every candidate); the posterior after y_j is the draws reweighted by
w_js ∝ p(y_j | θ_s, x, D) (importance sampling with the current posterior as proposal), so

    E_y[Var(T | D, y)] ≈ (1/J) Σ_j Σ_s w_js (T_s − T̄_j)²,

with the Kish ESS 1/Σ_s w_js² of each reweighting (its mean over j reported). The expected
information gain about every parameter (and learned noise scale) is the nested Monte Carlo
estimate EIG ≈ (1/J) Σ_j [ln p(y_j | θ_{s_j}) − ln (1/S) Σ_s p(y_j | θ_s)] [nats]; its inner
sum holds the draw θ_{s_j} that simulated y_j, which makes it a lower bound in expectation (at
most ln S), and its Monte Carlo error is large at the default J = 128 (0.14–0.37 nats over six
seeds for one bundled candidate): it ranks sets for the target ``all`` only.

Approximations: the S draws stand for the posterior (the weights' variance is the price: the
weighted variance is biased low where the ESS is small); the angle errors of a new row enter
linearised, as in the ``linearised`` likelihood; two new rows at one new θi setting are taken
with independent rotation errors (as if the sample were turned again for each), and a group
measured once so far (a sample, calibration or setting of one row) is taken as new. Where
the mean ESS falls below :data:`ESS_FLOOR` the importance estimate is replaced by the
linear-Gaussian (Bayes linear) one,
Var(T) − Cov(T, y) Var(y)⁻¹ Cov(y, T) over the joint predictive of (θ, y), which is exact
for a jointly normal (T, y) and needs no weights.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.scipy.special import logsumexp

# unrolled small factorisations, not LAPACK: batched LAPACK kernels split their batch over
# XLA's intra-op pool and wait for it, and two of them running at once can each hold a pool
# thread the other waits for (a hang of `design --budget 8`, seen in gdb: dpotrf and dtrsm in
# ParallelBatchMap, every other pool thread idle)
from brdf_infer._internal.lowrank import cholesky, solve_lower, solve_upper_transposed

ESS_FLOOR = 30.0  # mean Kish ESS below which the linear-Gaussian estimate is used


class RowPredictive(NamedTuple):
    """Each draw's conditional predictive of each candidate row's ln R given the measured rows.

    Attributes:
        mean: (S, C) μ_c + w_c·m_z [ln R].
        loading: (S, C, q) B = W_new L_C⁻ᵀ: the rows' shared part (cov of two rows: B_c·B_c').
        own: (S, C) d_c, the row's own variance [ln R²].
    """

    mean: jnp.ndarray
    loading: jnp.ndarray
    own: jnp.ndarray


class Outcome(NamedTuple):
    """Expected result of adding one set of rows (per candidate when vmapped).

    Attributes:
        variance_weighted: (P,) E_y[Var(T | D, y)] by importance reweighting.
        variance_linear: (P,) the linear-Gaussian estimate of the same.
        ess: mean Kish ESS of the reweightings.
        eig: expected information gain [nats].
    """

    variance_weighted: jnp.ndarray
    variance_linear: jnp.ndarray
    ess: jnp.ndarray
    eig: jnp.ndarray


def shared_effects(residual, factor, diagonal) -> tuple[jnp.ndarray, jnp.ndarray]:
    """(m_z, L_C) of the shared effects z | y, θ ~ N(m_z, C⁻¹), C = L_C L_Cᵀ (module docstring).

    Args:
        residual: (n,) y − μ(θ) of the measured rows [ln R].
        factor: (n, q) W.
        diagonal: (n,) D.
    """
    scaled = factor / diagonal[:, None]
    capacitance = jnp.eye(factor.shape[1]) + factor.T @ scaled
    lower = cholesky(capacitance)
    mean = solve_upper_transposed(lower, solve_lower(lower, scaled.T @ residual))
    return mean, lower


def row_predictive(residual, factor, diagonal, new_mean, new_factor, new_own) -> RowPredictive:
    """One draw's :class:`RowPredictive` of the candidates (vmap over draws for S).

    Args:
        residual, factor, diagonal: the measured rows (:func:`shared_effects`).
        new_mean: (C,) μ_c of the candidates [ln R].
        new_factor: (C, q) w_c: each candidate's loading on the measured rows' effects.
        new_own: (C,) d_c.
    """
    mean_z, lower = shared_effects(residual, factor, diagonal)
    loading = solve_lower(lower, new_factor.T).T  # W_new L_C⁻ᵀ
    return RowPredictive(new_mean + new_factor @ mean_z, loading, new_own)


def _set_moments(predictive: RowPredictive, rows: jnp.ndarray):
    """Mean (S, k) and covariance (S, k, k) of the rows ``rows`` (k indices) per draw."""
    mean = predictive.mean[:, rows]
    loading = predictive.loading[:, rows, :]
    covariance = jnp.einsum("skq,slq->skl", loading, loading)
    covariance = covariance + jax.vmap(jnp.diag)(predictive.own[:, rows])
    return mean, covariance


def set_outcome(
    predictive: RowPredictive,
    rows: jnp.ndarray,
    targets: jnp.ndarray,
    standard: jnp.ndarray,
    simulated_draws: jnp.ndarray,
) -> Outcome:
    """The expected outcome of measuring the rows ``rows`` (module docstring).

    Args:
        predictive: every draw's predictive of every candidate.
        rows: (k,) candidate indices of the set (repeats allowed: a setting measured twice).
        targets: (S, P) the target(s) of every draw.
        standard: (J, k) standard normals of the J simulated outcomes (common to candidates).
        simulated_draws: (J,) the draw each outcome is simulated from.
    """
    mean, covariance = _set_moments(predictive, rows)
    lower = jax.vmap(cholesky)(covariance)  # (S, k, k)
    outcomes = mean[simulated_draws] + jnp.einsum(
        "jkl,jl->jk", lower[simulated_draws], standard
    )  # (J, k)
    log_det = jnp.sum(jnp.log(jnp.diagonal(lower, axis1=1, axis2=2)), axis=1)  # (S,)
    identity = jnp.eye(lower.shape[-1])
    inverse = jax.vmap(lambda factor: solve_lower(factor, identity))(lower)  # L⁻¹ per draw

    def log_density(outcome):  # ln p(y_j | θ_s) for every s, up to a constant
        whitened = jnp.einsum("skl,sl->sk", inverse, outcome[None, :] - mean)
        return -0.5 * jnp.sum(whitened**2, axis=1) - log_det

    log_p = jax.vmap(log_density)(outcomes)  # (J, S)
    count = targets.shape[0]
    log_norm = logsumexp(log_p, axis=1, keepdims=True)
    weights = jnp.exp(log_p - log_norm)
    centred_mean = weights @ targets  # (J, P)
    variance = weights @ targets**2 - centred_mean**2
    ess = 1.0 / jnp.sum(weights**2, axis=1)
    own = jnp.take_along_axis(log_p, simulated_draws[:, None], axis=1)[:, 0]
    eig = jnp.mean(own - log_norm[:, 0] + jnp.log(count))
    return Outcome(
        variance_weighted=jnp.maximum(jnp.mean(variance, axis=0), 0.0),
        variance_linear=_linear_variance(mean, covariance, targets),
        ess=jnp.mean(ess),
        eig=jnp.maximum(eig, 0.0),
    )


def _linear_variance(mean, covariance, targets) -> jnp.ndarray:
    """Var(T) − Cov(T, y) Var(y)⁻¹ Cov(y, T) over the joint predictive, per target (P,)."""
    centred_t = targets - jnp.mean(targets, axis=0)
    centred_y = mean - jnp.mean(mean, axis=0)
    count = targets.shape[0]
    cross = centred_y.T @ centred_t / count  # (k, P)
    total = centred_y.T @ centred_y / count + jnp.mean(covariance, axis=0)  # (k, k)
    explained = jnp.sum(solve_lower(cholesky(total), cross) ** 2, axis=0)  # crossᵀ total⁻¹ cross
    return jnp.maximum(jnp.mean(centred_t**2, axis=0) - explained, 0.0)


@partial(jax.jit, static_argnames="batch")
def candidate_outcomes(
    predictive: RowPredictive,
    chosen: jnp.ndarray,
    targets: jnp.ndarray,
    standard: jnp.ndarray,
    simulated_draws: jnp.ndarray,
    batch: int = 8,
) -> Outcome:
    """:func:`set_outcome` of (chosen + one candidate) for every candidate, one compiled call
    (mapped over candidates in batches of ``batch`` to bound memory); compiles once per set
    size. Fields have a leading candidate axis."""
    count = predictive.mean.shape[1]

    def one(candidate):
        rows = jnp.concatenate([chosen, candidate[None]])
        return set_outcome(predictive, rows, targets, standard, simulated_draws)

    return jax.lax.map(one, jnp.arange(count), batch_size=batch)
