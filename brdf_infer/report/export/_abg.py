"""Harvey's ABg scatter model fitted to the model's BRDF, with the TIS preserved.

ABg (Harvey 1976; the scatter model of Zemax, FRED, ASAP, TracePro):

    BSDF(β) = A / (B + |β − β₀|^g)        [sr⁻¹],

with β and β₀ the projections of the scattered and the specular unit vectors onto the
surface plane (|β₀| = sin θi). Since cos θ dΩ = d²β, its TIS is

    TIS_ABg(θi) = A · I(B, g, sin θi),     I = ∫_{|β| ≤ 1} d²β / (B + |β − β₀|^g).

Per angle of incidence, A is fixed by TIS_ABg = TIS of the model (Eq. 9), and (B, g) are the
least-squares fit of ln BSDF to ln BRDF of Eqs. (7), (8), (10) over the hemisphere, each
direction weighted by cos θ sin θ dθ dφ (the share of the scattered power it stands for).

The fit uses a coarse quadrature of I (:func:`brdf_infer.model.abg_integral`); A is then
set with a precise one (relative error ≈ 1e-10) and ``tis_abg`` recomputed with a finer one,
which shows the TIS preserved.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from brdf_infer.model import (
    CHECK_QUADRATURE,
    PRECISE_QUADRATURE,
    Quadrature,
    abg_integral,
    abg_log_bsdf,
    beta_distance,
    log_brdf_hemisphere,
)
from brdf_infer.model.params import HemisphereConstants, Params

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
