"""Full-hemisphere BRDF, Eq. (8): azimuthal blend of the forward and backward branches.

Convention of the paper (Sec. 4.1, Fig. 9): the forward-scattering half of the specular plane
lies at φ = 180°, the backward half at φ = 0°; θ ∈ [0°, 90°] is the polar angle.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax.typing import ArrayLike

from brdf_infer.model._inplane import log_brdf_inplane
from brdf_infer.model.params import PAPER_CONSTANTS, HemisphereConstants, Params


def azimuthal_half_width(
    theta_i_deg: ArrayLike, constants: HemisphereConstants = PAPER_CONSTANTS
) -> jnp.ndarray:
    """Δφ = c1·θi + c2 of Eq. (8) [deg]."""
    return constants.c1 * jnp.asarray(theta_i_deg, float) + constants.c2_deg


def azimuthal_weight(
    theta_i_deg: ArrayLike, phi_deg: ArrayLike, constants: HemisphereConstants = PAPER_CONSTANTS
) -> jnp.ndarray:
    """Weight w(φ) of Eq. (8): 1 − |φ − 180°|/Δφ inside Δφ of the forward plane, else 0.

    φ is taken modulo 360°. A non-positive Δφ gives w = 0 everywhere.
    """
    distance = jnp.abs(jnp.mod(jnp.asarray(phi_deg, float), 360.0) - 180.0)
    half_width = azimuthal_half_width(theta_i_deg, constants)
    positive = half_width > 0
    safe_width = jnp.where(positive, half_width, 1.0)
    return jnp.where(positive, jnp.clip(1.0 - distance / safe_width, 0.0, 1.0), 0.0)


def azimuthal_weight_integral(
    theta_i_deg: ArrayLike, constants: HemisphereConstants = PAPER_CONSTANTS
) -> jnp.ndarray:
    """∫₀³⁶⁰ w(φ) dφ in closed form [deg]: Δφ for 0 < Δφ ≤ 180°, 360 − 180²/Δφ above."""
    half_width = azimuthal_half_width(theta_i_deg, constants)
    safe_width = jnp.where(half_width > 180.0, half_width, 180.0)
    return jnp.where(
        half_width <= 0.0,
        0.0,
        jnp.where(half_width <= 180.0, half_width, 360.0 - 180.0**2 / safe_width),
    )


def log_brdf_hemisphere(
    theta_i_deg: ArrayLike,
    theta_deg: ArrayLike,
    phi_deg: ArrayLike,
    params: Params,
    fold: bool = False,
    constants: HemisphereConstants = PAPER_CONSTANTS,
) -> jnp.ndarray:
    """ln BRDF(θi, θ, φ) of Eq. (8): ln[w·BRDF⁺ + (1 − w)·BRDF⁻].

    BRDF⁺ = Eq. (7) at θs = θ (times the fold of Eq. (10) when ``fold``), BRDF⁻ = Eq. (7)
    at θs = −θ. The blend is a weighted log-sum-exp, finite where either branch under- or
    overflows.

    Args:
        theta_i_deg: incidence angle θi [deg].
        theta_deg: polar scattering angle θ [deg], 0 ≤ θ ≤ 90.
        phi_deg: azimuth φ [deg], forward-scattering plane at 180°.
        params: ``Params`` in paper units.
        fold: include the folding term of Eq. (10) in BRDF⁺ (default: the physical BRDF).
        constants: Δφ and folding constants.

    Returns:
        ln BRDF [ln sr⁻¹].
    """
    theta = jnp.asarray(theta_deg, float)
    log_forward = log_brdf_inplane(theta_i_deg, theta, params, fold, constants)
    log_backward = log_brdf_inplane(theta_i_deg, -theta, params, False, constants)
    weight = azimuthal_weight(theta_i_deg, phi_deg, constants)
    log_forward, log_backward, weight = jnp.broadcast_arrays(log_forward, log_backward, weight)
    return jax.nn.logsumexp(
        jnp.stack([log_forward, log_backward]), axis=0, b=jnp.stack([weight, 1.0 - weight])
    )


def brdf_hemisphere(
    theta_i_deg: ArrayLike,
    theta_deg: ArrayLike,
    phi_deg: ArrayLike,
    params: Params,
    fold: bool = False,
    constants: HemisphereConstants = PAPER_CONSTANTS,
) -> jnp.ndarray:
    """BRDF(θi, θ, φ) of Eq. (8) (with Eq. 10 when ``fold``) [sr⁻¹]; see
    :func:`log_brdf_hemisphere`."""
    return jnp.exp(log_brdf_hemisphere(theta_i_deg, theta_deg, phi_deg, params, fold, constants))
