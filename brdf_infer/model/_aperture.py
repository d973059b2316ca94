"""Raw reflectance ↔ BRDF through the detector aperture's solid angle, Eq. (6)."""

from __future__ import annotations

import jax.numpy as jnp
from jax.typing import ArrayLike

from brdf_infer._internal.units import DEG


def solid_angle(d_mm: ArrayLike, r_mm: ArrayLike) -> jnp.ndarray:
    """Solid angle Ω = 2π(1 − cos ρ), ρ = d/(2r), of a circular aperture (Sec. 5.3).

    Evaluated as 4π sin²(ρ/2), which equals 2π(1 − cos ρ) without cancellation.

    Args:
        d_mm: aperture diameter [mm].
        r_mm: aperture–sample distance [mm].

    Returns:
        Ω [sr].
    """
    rho = jnp.asarray(d_mm, float) / (2.0 * jnp.asarray(r_mm, float))
    return 4.0 * jnp.pi * jnp.sin(0.5 * rho) ** 2


def reflectance_to_brdf(
    reflectance: ArrayLike, theta_s_deg: ArrayLike, d_mm: ArrayLike, r_mm: ArrayLike
) -> jnp.ndarray:
    """BRDF = R / (Ω cos θs), Eq. (6).

    Args:
        reflectance: raw reflectance dPs/Pi of Eq. (2) [-].
        theta_s_deg: scattering angle θs [deg].
        d_mm: detector aperture diameter [mm].
        r_mm: aperture–sample distance [mm].

    Returns:
        BRDF [sr⁻¹].
    """
    cos_s = jnp.cos(jnp.asarray(theta_s_deg, float) * DEG)
    return jnp.asarray(reflectance, float) / (solid_angle(d_mm, r_mm) * cos_s)


def brdf_to_reflectance(
    brdf: ArrayLike, theta_s_deg: ArrayLike, d_mm: ArrayLike, r_mm: ArrayLike
) -> jnp.ndarray:
    """Raw reflectance R = BRDF · Ω · cos θs, the inverse of Eq. (6).

    Args:
        brdf: BRDF [sr⁻¹].
        theta_s_deg: scattering angle θs [deg].
        d_mm: detector aperture diameter [mm].
        r_mm: aperture–sample distance [mm].

    Returns:
        Raw reflectance [-].
    """
    cos_s = jnp.cos(jnp.asarray(theta_s_deg, float) * DEG)
    return jnp.asarray(brdf, float) * solid_angle(d_mm, r_mm) * cos_s


def log_aperture_factor(theta_s_deg: ArrayLike, d_mm: ArrayLike, r_mm: ArrayLike) -> jnp.ndarray:
    """ln(Ω cos θs): ln R = ln BRDF + this, Eq. (6) in log space (|θs| < 90°)."""
    cos_s = jnp.cos(jnp.asarray(theta_s_deg, float) * DEG)
    return jnp.log(solid_angle(d_mm, r_mm)) + jnp.log(cos_s)
