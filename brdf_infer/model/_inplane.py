"""In-specular-plane BRDF, Eq. (7), with the optional folding term of Eq. (10).

Everything is computed as ln BRDF: the exponent of Eq. (7) can exceed the float64 range for
extreme coefficients, while its logarithm stays finite.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
from jax.scipy.special import log_ndtr
from jax.typing import ArrayLike

from brdf_infer.model.params import PAPER_CONSTANTS, HemisphereConstants, Params

_SQRT2 = math.sqrt(2.0)


def positive_power(x: ArrayLike, alpha: ArrayLike) -> jnp.ndarray:
    """x^α for x > 0 and 0 for x ≤ 0, with finite gradients everywhere (double-where).

    Computed as exp(α ln x) on a guarded argument, so neither the value nor the gradient
    with respect to x or α is NaN at x = 0 or below (also for α ≤ 1).
    """
    x = jnp.asarray(x, float)
    positive = x > 0
    safe_x = jnp.where(positive, x, 1.0)
    return jnp.where(positive, jnp.exp(alpha * jnp.log(safe_x)), 0.0)


def log_fold(theta_s_deg: ArrayLike, constants: HemisphereConstants = PAPER_CONSTANTS):
    """ln of the folding factor {1 − erf[a(θs − θsf)]}/2 of Eq. (10).

    Uses erfc(z)/2 = Φ(−√2 z) and ``log_ndtr``: finite far into both tails (no 1 − erf).

    Args:
        theta_s_deg: scattering angle [deg].
        constants: ``fold_a_per_deg`` [deg⁻¹] and ``fold_theta_sf_deg`` [deg].
    """
    z = constants.fold_a_per_deg * (jnp.asarray(theta_s_deg, float) - constants.fold_theta_sf_deg)
    return log_ndtr(-_SQRT2 * z)


def fold_statement(fold: bool) -> str:
    """What a product says about Eq. (10): its folding is a measurement artefact (Sec. 5 of
    the article), added there only to compare with Table 3; without it the BRDF is the
    physical one and its TIS the larger, conservative one for a stray-light budget."""
    if fold:
        return (
            "Eq. (10) folding: included (the article's measurement artefact, as in its "
            "Table 3; less scatter near grazing, not conservative for stray light)"
        )
    return "Eq. (10) folding: not included (physical BRDF, conservative for stray light)"


def log_brdf_inplane(
    theta_i_deg: ArrayLike,
    theta_s_deg: ArrayLike,
    params: Params,
    fold: bool = False,
    constants: HemisphereConstants = PAPER_CONSTANTS,
) -> jnp.ndarray:
    """ln BRDF(θi, θs) of Eq. (7); with ``fold``, times Eq. (10)'s factor on the forward side.

    ln BRDF = ln BRDF0 + a1 θi x + (a2 θi + a3 θi²) x^α with x = θs − θs0 for θs ≥ θs0,
    and ln BRDF0 below θs0. Inputs broadcast against each other and against the fields of
    ``params``.

    Args:
        theta_i_deg: incidence angle θi [deg].
        theta_s_deg: in-plane scattering angle θs [deg], > 0 on the forward side.
        params: ``Params`` in paper units.
        fold: apply Eq. (10) for θs ≥ 0 (the forward branch BRDF⁺).
        constants: folding constants.

    Returns:
        ln BRDF [ln sr⁻¹].
    """
    theta_i = jnp.asarray(theta_i_deg, float)
    theta_s = jnp.asarray(theta_s_deg, float)
    x = theta_s - params.theta_s0
    x_linear = jnp.where(x > 0, x, 0.0)
    x_alpha = positive_power(x, params.alpha)
    exponent = params.a1 * theta_i * x_linear + (params.a2 * theta_i + params.a3 * theta_i**2) * (
        x_alpha
    )
    log_brdf = jnp.log(params.brdf0) + exponent
    if fold:
        log_brdf = log_brdf + jnp.where(theta_s >= 0, log_fold(theta_s, constants), 0.0)
    return log_brdf


def brdf_inplane(
    theta_i_deg: ArrayLike,
    theta_s_deg: ArrayLike,
    params: Params,
    fold: bool = False,
    constants: HemisphereConstants = PAPER_CONSTANTS,
) -> jnp.ndarray:
    """BRDF(θi, θs) of Eq. (7) [sr⁻¹]; see :func:`log_brdf_inplane` for the arguments."""
    return jnp.exp(log_brdf_inplane(theta_i_deg, theta_s_deg, params, fold, constants))
