"""Scatter lobes of the ray tracers in direction cosines: ABg and Harvey–Shack, and their TIS.

β and β₀ are the projections of the scattered and the specular unit vectors onto the surface
plane (|β| = sin θ, |β₀| = sin θi). In the paper's frame (forward-scattering plane at
φ = 180°, Sec. 4.1) β = sin θ (cos φ, sin φ) and β₀ = (−sin θi, 0). Both lobes depend on
ρ = |β − β₀| only:

    ABg (Harvey 1976):      BSDF = A / (B + ρ^g)                       [sr⁻¹]
    Harvey–Shack:           BSDF = b₀ [1 + (ρ/L)²]^(S/2)               [sr⁻¹]

Since cos θ dΩ = d²β, the TIS of a lobe is its integral over the unit disk |β| ≤ 1,
computed in polar coordinates about β₀: ψ ∈ [0, π] (mirror symmetry) by composite
Gauss–Legendre, and the radial integral ∫₀^R ρ f(ρ) dρ in s = ln ρ with panels packed around
the lobe's knee (ρ_k = B^(1/g) for ABg, L for Harvey–Shack), where the integrand turns from
e^{2s} f(0) to its power-law tail.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer._internal.units import DEG

_KNEE_OFFSETS = np.arange(-5.0, 5.5, 1.0)  # panel edges around the knee, in s = ln ρ
_TAIL = 25.0  # below the knee − 25 the integrand is e^{2s} f(0) to 1e-10 or better
_WIDENING = 0.5 * 2.0 ** np.arange(8)  # 0.5, 1, 2, …, 64


@dataclass(frozen=True)
class Quadrature:
    """Node counts of the unit-disk quadrature."""

    azimuth_panels: int = 8
    azimuth_nodes: int = 12
    radial_nodes: int = 8


FIT_QUADRATURE = Quadrature()
PRECISE_QUADRATURE = Quadrature(azimuth_panels=24, azimuth_nodes=16, radial_nodes=16)
CHECK_QUADRATURE = Quadrature(azimuth_panels=40, azimuth_nodes=20, radial_nodes=24)


def gauss_legendre(lower, upper, nodes: int):
    """Nodes and weights of Gauss–Legendre on [lower, upper] (arrays broadcast)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    half = (jnp.asarray(upper) - jnp.asarray(lower))[..., None] / 2.0
    middle = (jnp.asarray(upper) + jnp.asarray(lower))[..., None] / 2.0
    return middle + half * x, half * w


def _radial_integral(log_r, knee, log_f: Callable, log_f0, nodes: int):
    """∫₀^R ρ f(ρ) dρ for R = e^{log_r}; ``log_f(s)`` = ln f(e^s), ``log_f0`` = ln f(0).

    Panels of width 1 within 5 of the knee, widening geometrically away from the knee and
    from ln R, a last panel 25 below the knee, and ∫ below it as f(0) ρ²/2.
    """
    knee = jnp.minimum(knee, log_r)
    widening = jnp.asarray(_WIDENING)
    edges = jnp.concatenate(
        [
            jnp.array([knee - _TAIL, log_r]),
            knee + _KNEE_OFFSETS,
            knee + _KNEE_OFFSETS[-1] + widening,
            log_r - widening,
        ]
    )
    edges = jnp.sort(jnp.clip(edges, knee - _TAIL, log_r))
    s, w = gauss_legendre(edges[:-1], edges[1:], nodes)
    tail = jnp.exp(2.0 * (knee - _TAIL) + log_f0) / 2.0
    return jnp.sum(w * jnp.exp(2.0 * s + log_f(s))) + tail


def disk_integral(log_f: Callable, knee, log_f0, sin_theta_i, quadrature: Quadrature):
    """∫_{|β| ≤ 1} f(|β − β₀|) d²β for |β₀| = ``sin_theta_i`` (scalar arguments).

    Args:
        log_f: ln f as a function of s = ln ρ (elementwise).
        knee: ln ρ where f bends from flat to its tail.
        log_f0: ln f(0).
        sin_theta_i: |β₀|.
        quadrature: node counts.
    """
    edges = jnp.linspace(0.0, jnp.pi, quadrature.azimuth_panels + 1)
    psi, w = gauss_legendre(edges[:-1], edges[1:], quadrature.azimuth_nodes)
    psi, w = psi.reshape(-1), w.reshape(-1)
    b = jnp.asarray(sin_theta_i, float)
    reach = -b * jnp.cos(psi) + jnp.sqrt(1.0 - (b * jnp.sin(psi)) ** 2)  # |β| = 1 along ψ
    inner = jax.vmap(
        lambda r: _radial_integral(jnp.log(r), knee, log_f, log_f0, quadrature.radial_nodes)
    )
    return 2.0 * jnp.sum(w * inner(reach))


def beta_distance(theta_i_deg, theta_deg, phi_deg):
    """ρ = |β − β₀|, β = sin θ (cos φ, sin φ), β₀ = (−sin θi, 0) (the specular direction).

    Computed as |2 sin((θ − θi)/2) cos((θ + θi)/2)| in the plane of incidence, so that
    it is exact there; out of the plane from the components.
    """
    sin_theta = jnp.sin(jnp.asarray(theta_deg, float) * DEG)
    phi = jnp.asarray(phi_deg, float) * DEG
    dx = sin_theta * jnp.cos(phi) + jnp.sin(jnp.asarray(theta_i_deg, float) * DEG)
    dy = sin_theta * jnp.sin(phi)
    squared = dx**2 + dy**2
    positive = squared > 0.0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, squared, 1.0)), 0.0)


def _log_power(rho, exponent):
    """ln ρ^exponent, −∞ at ρ = 0 (double-where: finite gradients there)."""
    positive = rho > 0.0
    return jnp.where(positive, exponent * jnp.log(jnp.where(positive, rho, 1.0)), -jnp.inf)


def abg_log_bsdf(log_a, log_b, g, rho):
    """ln BSDF = ln A − ln(B + ρ^g) of ABg [ln sr⁻¹]; ρ^g = 0 at ρ = 0 (g > 0)."""
    return log_a - jnp.logaddexp(log_b, _log_power(rho, g))


def abg_integral(log_b, g, sin_theta_i, quadrature: Quadrature = FIT_QUADRATURE):
    """I(B, g, b) = ∫_{|β| ≤ 1} d²β / (B + |β − β₀|^g): TIS_ABg = A · I (scalar arguments)."""
    return disk_integral(
        lambda s: -jnp.logaddexp(log_b, g * s), log_b / g, -log_b, sin_theta_i, quadrature
    )


def harvey_shack_log_bsdf(log_b0, log_l, slope, rho):
    """ln BSDF = ln b₀ + (S/2) ln[1 + (ρ/L)²] of Harvey–Shack [ln sr⁻¹]."""
    return log_b0 + 0.5 * slope * jnp.log1p(jnp.exp(2.0 * (_log_power(rho, 1.0) - log_l)))


def harvey_shack_integral(log_l, slope, sin_theta_i, quadrature: Quadrature = PRECISE_QUADRATURE):
    """∫_{|β| ≤ 1} [1 + (|β − β₀|/L)²]^(S/2) d²β: TIS_HS = b₀ · this (scalar arguments)."""
    return disk_integral(
        lambda s: 0.5 * slope * jnp.log1p(jnp.exp(2.0 * (s - log_l))),
        log_l,
        0.0,
        sin_theta_i,
        quadrature,
    )
