"""Harvey's ABg scatter model fitted to the model's BRDF, with the TIS preserved.

ABg (Harvey 1976; the scatter model of Zemax, FRED, ASAP, TracePro):

    BSDF(β) = A / (B + |β − β₀|^g)        [sr⁻¹],

with β and β₀ the projections of the scattered and the specular unit vectors onto the
surface plane (|β₀| = sin θi). Since cos θ dΩ = d²β, its TIS is

    TIS_ABg(θi) = A · I(B, g, sin θi),     I = ∫_{|β| ≤ 1} d²β / (B + |β − β₀|^g).

Per angle of incidence, A is fixed by TIS_ABg = TIS of the model (Eq. 9), and (B, g) are the
least-squares fit of ln BSDF to ln BRDF of Eqs. (7), (8), (10) over the hemisphere, each
direction weighted by cos θ sin θ dθ dφ (the share of the scattered power it stands for).

The fit uses a coarse quadrature of I; A is then set with a precise one (relative error
≈ 1e-10) and ``tis_abg`` recomputed with a finer one, which shows the TIS preserved.
I is computed in polar coordinates about β₀: ψ ∈ [0, π] (mirror symmetry) by composite
Gauss–Legendre, and the radial integral ∫₀^R ρ dρ / (B + ρ^g) in s = ln ρ with panels
packed around the knee s = ln(B)/g, where the integrand turns from e^{2s}/B to e^{(2−g)s}.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from brdf_infer.model import log_brdf_hemisphere
from brdf_infer.params import HemisphereConstants, Params

_KNEE_OFFSETS = np.arange(-5.0, 5.5, 1.0)  # panel edges around the knee, in s = ln ρ
_TAIL = 25.0  # the integrand is e^{2(s − s_knee)} of its knee value below the knee
_WIDENING = 0.5 * 2.0 ** np.arange(8)  # 0.5, 1, 2, …, 64


@dataclass(frozen=True)
class Quadrature:
    """Node counts of the I(B, g, b) quadrature."""

    azimuth_panels: int = 8
    azimuth_nodes: int = 12
    radial_nodes: int = 8


FIT_QUADRATURE = Quadrature()
PRECISE_QUADRATURE = Quadrature(azimuth_panels=24, azimuth_nodes=16, radial_nodes=16)
CHECK_QUADRATURE = Quadrature(azimuth_panels=40, azimuth_nodes=20, radial_nodes=24)


def _gauss_legendre(lower, upper, nodes: int):
    """Nodes and weights of Gauss–Legendre on [lower, upper] (arrays broadcast)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    half = (jnp.asarray(upper) - jnp.asarray(lower))[..., None] / 2.0
    middle = (jnp.asarray(upper) + jnp.asarray(lower))[..., None] / 2.0
    return middle + half * x, half * w


def _radial_integral(log_r, log_b, g, nodes: int):
    """∫₀^R ρ dρ / (B + ρ^g) for R = e^{log_r} (scalar arguments).

    Panels of width 1 within 5 of the knee, widening geometrically away from the knee and
    from ln R (where e^{(2−g)s} is largest for g < 2), a last panel 25 below the knee, and
    ∫ below it as ρ²/(2B).
    """
    knee = jnp.minimum(log_b / g, log_r)
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
    s, w = _gauss_legendre(edges[:-1], edges[1:], nodes)
    # e^{2s} / (B + e^{gs}) in log space
    log_integrand = 2.0 * s - jnp.logaddexp(log_b, g * s)
    tail = jnp.exp(2.0 * (knee - _TAIL) - log_b) / 2.0
    return jnp.sum(w * jnp.exp(log_integrand)) + tail


def abg_integral(log_b, g, sin_theta_i, quadrature: Quadrature = FIT_QUADRATURE):
    """I(B, g, b) = ∫_{|β| ≤ 1} d²β / (B + |β − β₀|^g), |β₀| = b (scalar arguments)."""
    edges = jnp.linspace(0.0, jnp.pi, quadrature.azimuth_panels + 1)
    psi, w = _gauss_legendre(edges[:-1], edges[1:], quadrature.azimuth_nodes)
    psi, w = psi.reshape(-1), w.reshape(-1)
    b = jnp.asarray(sin_theta_i, float)
    reach = -b * jnp.cos(psi) + jnp.sqrt(1.0 - (b * jnp.sin(psi)) ** 2)  # |β| = 1 along ψ
    inner = jax.vmap(lambda r: _radial_integral(jnp.log(r), log_b, g, quadrature.radial_nodes))
    return 2.0 * jnp.sum(w * inner(reach))


def abg_log_bsdf(log_a, log_b, g, beta_distance):
    """ln BSDF = ln A − ln(B + |β − β₀|^g); |β − β₀|^g = 0 at β = β₀ (g > 0)."""
    positive = beta_distance > 0.0
    safe = jnp.where(positive, beta_distance, 1.0)
    log_power = jnp.where(positive, g * jnp.log(safe), -jnp.inf)
    return log_a - jnp.logaddexp(log_b, log_power)


def abg_bsdf(a, b, g, theta_i_deg, theta_deg, phi_deg):
    """ABg BSDF [sr⁻¹] at (θ, φ) of the model's frame (forward plane at φ = 180°)."""
    return jnp.exp(
        abg_log_bsdf(jnp.log(a), jnp.log(b), g, beta_distance(theta_i_deg, theta_deg, phi_deg))
    )


def beta_distance(theta_i_deg, theta_deg, phi_deg):
    """|β − β₀|: β = sin θ (cos φ, sin φ), β₀ = (−sin θi, 0) (the specular direction)."""
    sin_theta = jnp.sin(jnp.radians(theta_deg))
    phi = jnp.radians(phi_deg)
    dx = sin_theta * jnp.cos(phi) + jnp.sin(jnp.radians(theta_i_deg))
    dy = sin_theta * jnp.sin(phi)
    return jnp.hypot(dx, dy)


# ---------------------------------------------------------------------------- fit

LOG_KNEE_RANGE = (np.log(1e-4), np.log(100.0))  # ρ_k = B^(1/g), where the power law bends
G_RANGE = (0.02, 6.0)
_GRID = np.stack(
    np.meshgrid(np.linspace(*LOG_KNEE_RANGE, 24), np.linspace(0.1, 5.9, 30), indexing="ij"), -1
).reshape(-1, 2)  # coarse (ln ρ_k, g) search before Levenberg–Marquardt


def fit_directions(theta_step_deg: float = 2.0, phi_step_deg: float = 10.0):
    """Midpoint grid over the half hemisphere φ ∈ [0°, 180°] and its cos θ sin θ dθ dφ weights.

    Returns:
        (θ, φ, weight) flattened [deg, deg, -]; the weights sum to ≈ π/2.
    """
    theta = np.arange(theta_step_deg / 2, 90.0, theta_step_deg)
    phi = np.arange(phi_step_deg / 2, 180.0, phi_step_deg)
    grid_theta, grid_phi = np.meshgrid(theta, phi, indexing="ij")
    weight = (
        np.cos(np.radians(grid_theta))
        * np.sin(np.radians(grid_theta))
        * np.radians(theta_step_deg)
        * np.radians(phi_step_deg)
    )
    return grid_theta.reshape(-1), grid_phi.reshape(-1), weight.reshape(-1)


def _between(y, low, high):
    return low + (high - low) * jax.nn.sigmoid(y)


def _inside(value, low, high):
    ratio = jnp.clip((jnp.asarray(value, float) - low) / (high - low), 1e-9, 1 - 1e-9)
    return jnp.log(ratio) - jnp.log1p(-ratio)


def _shape(y):
    """(ln B, g) from the unconstrained y: ln ρ_k and g, each bounded by a logistic map.

    (ln ρ_k, g) rather than (ln B, g): the knee ρ_k = B^(1/g) and the slope g are nearly
    independent in the fit, where ln B and g trade off along a long valley.
    """
    log_knee, g = _between(y[0], *LOG_KNEE_RANGE), _between(y[1], *G_RANGE)
    return g * log_knee, g


def _unconstrained(log_b, g):
    return jnp.stack([_inside(log_b / g, *LOG_KNEE_RANGE), _inside(g, *G_RANGE)])


def _residuals_of_shape(log_b, g, data):
    log_target, log_tis, distance, root_weight, sin_theta_i = data
    log_a = log_tis - jnp.log(abg_integral(log_b, g, sin_theta_i))
    return root_weight * (abg_log_bsdf(log_a, log_b, g, distance) - log_target)


def _residuals(y, data):
    return _residuals_of_shape(*_shape(y), data)


def _fit_data(theta_i_deg, log_tis, params: Params, fold: bool, constants):
    theta, phi, weight = (jnp.asarray(v) for v in fit_directions())
    log_target = log_brdf_hemisphere(theta_i_deg, theta, phi, params, fold, constants)
    distance = beta_distance(theta_i_deg, theta, phi)
    sin_theta_i = jnp.sin(jnp.radians(theta_i_deg))
    return log_target, log_tis, distance, jnp.sqrt(weight), sin_theta_i


def _refine(start, data, max_steps: int):
    """Levenberg–Marquardt from ``start`` = (ln B, g): (ln A, ln B, g, rms ln error).

    Between θi ≈ 10° and 45° the loss has a long flat valley in (ρ_k, g); the steps cap
    stops the creep along it once the loss no longer changes (measured on ``uv-paper``: 40
    steps from a nearby fit leave the loss within 1e-3 relative of 400 steps).
    """
    solver = optx.LevenbergMarquardt(rtol=1e-5, atol=1e-7)
    y0 = _unconstrained(*start)
    solution = optx.least_squares(
        _residuals, solver, y0, args=data, max_steps=max_steps, throw=False
    )
    log_b, g = _shape(solution.value)
    log_a = data[1] - jnp.log(abg_integral(log_b, g, data[4]))
    loss = jnp.sum(_residuals(solution.value, data) ** 2)
    return log_a, log_b, g, jnp.sqrt(loss / jnp.sum(data[3] ** 2))


@partial(jax.jit, static_argnames=("fold",))
def _fit_searched(theta_i_deg, log_tis, params: Params, fold: bool, constants):
    """One θi: coarse search over (ln ρ_k, g), then Levenberg–Marquardt from the best point."""
    data = _fit_data(theta_i_deg, log_tis, params, fold, constants)
    losses = jax.lax.map(
        lambda point: jnp.sum(_residuals_of_shape(point[1] * point[0], point[1], data) ** 2),
        jnp.asarray(_GRID),
        batch_size=64,
    )
    best = jnp.argmin(jnp.where(jnp.isfinite(losses), losses, jnp.inf))
    log_knee, g = jnp.asarray(_GRID)[best]
    return _refine((g * log_knee, g), data, 200)


@partial(jax.jit, static_argnames=("fold",))
def _fit_started(theta_i_deg, log_tis, params: Params, fold: bool, constants, start):
    """Every θi at once, Levenberg–Marquardt from given (ln B, g) starts, shape (n, 2)."""
    fit = jax.vmap(
        lambda t, lt, s: _refine(s, _fit_data(t, lt, params, fold, constants), 40),
    )
    return fit(theta_i_deg, log_tis, start)


def _integrals(quadrature: Quadrature):
    return jax.jit(jax.vmap(lambda lb, g, b: abg_integral(lb, g, b, quadrature)))


_precise_integral = _integrals(PRECISE_QUADRATURE)
_check_integral = _integrals(CHECK_QUADRATURE)


@dataclass
class AbgFit:
    """ABg fits per angle of incidence (arrays over ``batch × θi``).

    Attributes:
        theta_i_deg: angles of incidence [deg].
        a: A [sr⁻¹]; b: B [-]; g: g [-].
        tis_model: TIS of the model, Eq. (9).
        tis_abg: A · I(B, g) with a finer quadrature than the one that set A.
        rms_log_error: cos θ sin θ-weighted rms of ln BSDF_ABg − ln BRDF over the hemisphere.
    """

    theta_i_deg: np.ndarray
    a: np.ndarray
    b: np.ndarray
    g: np.ndarray
    tis_model: np.ndarray
    tis_abg: np.ndarray
    rms_log_error: np.ndarray


def fit_abg(
    theta_i_deg,
    params: Params,
    tis_model: np.ndarray,
    fold: bool,
    constants: HemisphereConstants,
    start: AbgFit | None = None,
) -> AbgFit:
    """TIS-preserving ABg fits of one parameter set at every θi.

    Args:
        theta_i_deg: angles of incidence [deg], shape (n,).
        params: one parameter set (scalar fields).
        tis_model: the model's TIS at ``theta_i_deg`` (Eq. 9).
        fold: include Eq. (10) in the model's BRDF.
        constants: Δφ and folding constants.
        start: a fit at the same angles to start from (e.g. of nearby parameters); without
            it, each θi starts from the best point of a coarse (ln ρ_k, g) search.

    Returns:
        The fit at every θi.
    """
    theta_i = np.asarray(theta_i_deg, float).reshape(-1)
    log_tis = np.log(np.asarray(tis_model, float).reshape(-1))
    if start is None:
        rows = [
            _fit_searched(float(t), float(lt), params, fold, constants)
            for t, lt in zip(theta_i, log_tis, strict=True)
        ]
        log_a, log_b, g, rms = (np.array([float(r[k]) for r in rows]) for k in range(4))
    else:
        starts = np.stack([np.log(start.b), start.g], axis=-1)
        log_a, log_b, g, rms = (
            np.asarray(v) for v in _fit_started(theta_i, log_tis, params, fold, constants, starts)
        )
    sin_theta_i = np.sin(np.radians(theta_i))
    log_a = log_tis - np.log(np.asarray(_precise_integral(log_b, g, sin_theta_i)))
    tis_abg = np.exp(log_a) * np.asarray(_check_integral(log_b, g, sin_theta_i))
    return AbgFit(
        theta_i_deg=theta_i,
        a=np.exp(log_a),
        b=np.exp(log_b),
        g=g,
        tis_model=np.exp(log_tis),
        tis_abg=tis_abg,
        rms_log_error=rms,
    )
