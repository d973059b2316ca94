"""The whitening of the linear coefficients c = (ln BRDF0, b1, b2, b3) of Eq. (7): their
design at (α, θs0), a normal stand-in of their priors, and c = m + L⁻ᵀ u from the whitened
coordinates u (:mod:`._model`'s docstring says why)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from brdf_infer._internal.lowrank import (
    Whitened,
    cholesky,
    solve_lower,
    solve_upper_transposed,
)
from brdf_infer.model import positive_power
from brdf_infer.model.coordinates import ANGLE_SCALE_DEG
from brdf_infer.model.priors import Prior
from brdf_infer.predict.observations import Observations


def linear_design(rows: Observations, alpha, t_s0) -> jnp.ndarray:
    """Columns [1, t x', t x'^α, t² x'^α] of c = (ln BRDF0, b1, b2, b3) in ln BRDF (Eq. 7),
    t = θi/90°, x' = θs/90° − θs0/90° (zero below θs0)."""
    t = rows.theta_i_deg / ANGLE_SCALE_DEG
    x = rows.theta_s_deg / ANGLE_SCALE_DEG - t_s0
    x_linear = jnp.where(x > 0, x, 0.0)
    x_alpha = positive_power(x, alpha)
    return jnp.stack([jnp.ones_like(t), t * x_linear, t * x_alpha, t * t * x_alpha], axis=1)


def gaussian_moments(prior: Prior) -> tuple[float, float]:
    """Mean and sd of a non-fixed prior, as a normal stand-in for the whitening regression."""
    if prior.kind == "uniform":
        return 0.5 * (prior.lower + prior.upper), (prior.upper - prior.lower) / np.sqrt(12.0)
    return prior.loc, prior.scale  # normal; truncated normal: its untruncated moments suffice


def whitened_coefficients(
    design, target, factor, diagonal, prior_mean, prior_sd, standard, disjoint: int = 0
):
    """c = m + L⁻ᵀ u and ln|∂c/∂u| for the regression target = design·c + noise,
    Cov(noise) = D + W Wᵀ (Woodbury: the capacitance's small Cholesky, ``_internal.lowrank``).

    With the posterior precision P = L Lᵀ = diag(1/sd²) + Xᵀ Σ⁻¹ X and the right-hand side
    r = mean/sd² + Xᵀ Σ⁻¹ y, m = P⁻¹ r, so c = L⁻ᵀ (L⁻¹ r + u) with one solve each way.

    Args:
        design: (rows, k) columns of the free coefficients.
        target: (rows,) ln R minus everything that does not depend on c.
        factor: (rows, q) W.
        diagonal: (rows,) D.
        prior_mean, prior_sd: (k,) normal stand-in of the coefficients' prior.
        standard: (k,) the whitened coordinates u.
        disjoint: leading columns of W with non-overlapping rows (the per-sample effects).
    """
    whitened = Whitened(factor, diagonal, disjoint)
    columns = whitened.scale(jnp.concatenate([design, target[:, None]], axis=1))
    projected = whitened.project(columns)  # L_C⁻¹ Bᵀ [X' | y']
    gram = columns.T @ columns - projected.T @ projected  # [X | y]ᵀ Σ⁻¹ [X | y]
    free = design.shape[1]
    precision = jnp.diag(1.0 / prior_sd**2) + gram[:free, :free]
    rhs = prior_mean / prior_sd**2 + gram[:free, free]
    cholesky_factor = cholesky(precision)
    values = solve_upper_transposed(cholesky_factor, solve_lower(cholesky_factor, rhs) + standard)
    return values, -jnp.sum(jnp.log(jnp.diagonal(cholesky_factor)))
