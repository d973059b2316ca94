"""Total integrated scatter, Eq. (9), reduced exactly to a 1-D integral in θ.

With Eq. (8) the azimuthal integral is closed-form: ∫w dφ = W (see
:func:`azimuthal_weight_integral`), so

    TIS(θi) = ∫₀^{π/2} [W·BRDF⁺(θ) + (2π − W)·BRDF⁻(θ)] cos θ sin θ dθ.

The integrand has kinks where a branch reaches θs0 (at θ = |θs0|) and, with Eq. (10)'s
folding, a steep shoulder at the folding angle θsf; the integral is split there and each panel
uses Gauss–Legendre.

``fold`` defaults to False everywhere: the physical BRDF, whose TIS is the conservative one for
a stray-light budget. Eq. (10) models a measurement artefact (Sec. 5 of the article), added
there only to compare with Table 3; pass ``fold=True`` for that comparison.
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from brdf_infer._internal.units import DEG
from brdf_infer.model._hemisphere import azimuthal_weight_integral
from brdf_infer.model._inplane import log_brdf_inplane
from brdf_infer.model.params import PAPER_CONSTANTS, HemisphereConstants, Params

TIS_NODES = 64  # Gauss–Legendre nodes per panel; see tests/test_tis.py for the error
# Panels narrower than this are dropped: their contribution is below 1e-11 of the TIS, while
# nodes within ~1e-300° of θ = 0 make d ln(sin θ)/dθ overflow and the gradient NaN.
MIN_PANEL_WIDTH_DEG = 1e-9


def _gauss_legendre(nodes: int) -> tuple[np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(nodes)
    return x, w


def _panel_edges(params: Params, fold: bool, constants: HemisphereConstants) -> jnp.ndarray:
    """Sorted panel edges in [0°, 90°]: the ends, |θs0| and (with folding) θsf."""
    kinks = [jnp.clip(jnp.abs(params.theta_s0), 0.0, 90.0)]
    if fold:
        kinks.append(jnp.clip(jnp.asarray(constants.fold_theta_sf_deg, float), 0.0, 90.0))
    return jnp.concatenate([jnp.zeros(1), jnp.sort(jnp.stack(kinks)), jnp.full(1, 90.0)])


def _log_tis_single(
    theta_i_deg: jnp.ndarray,
    params: Params,
    fold: bool,
    constants: HemisphereConstants,
    nodes: int,
) -> jnp.ndarray:
    """ln TIS for one θi and one parameter set (scalars), accumulated in log space.

    Every quadrature term is ln(weight) + ln BRDF + ln(cos θ sin θ), summed by a weighted
    log-sum-exp, so a BRDF beyond the float64 range cannot turn a zero weight into NaN.
    Zero-width and sliver panels (coincident kinks, θs0 within ``MIN_PANEL_WIDTH_DEG`` of 0)
    are masked on their inputs (double where).
    """
    x, w = _gauss_legendre(nodes)
    edges = _panel_edges(params, fold, constants)
    lower, upper = edges[:-1, None], edges[1:, None]
    valid = upper - lower > MIN_PANEL_WIDTH_DEG
    half = jnp.where(valid, 0.5 * (upper - lower), 1.0)
    theta = jnp.where(valid, lower, 0.0) + half * (x[None, :] + 1.0)  # [deg], inside (0, 90)
    log_weight = jnp.log(half * DEG) + jnp.log(w)[None, :]  # dθ in radians
    log_projected = jnp.log(0.5 * jnp.sin(2.0 * theta * DEG))  # ln(cos θ sin θ)
    forward = log_brdf_inplane(theta_i_deg, theta, params, fold, constants)
    backward = log_brdf_inplane(theta_i_deg, -theta, params, False, constants)
    terms = jnp.stack([forward, backward]) + log_weight + log_projected
    terms = jnp.where(valid[None], terms, -jnp.inf)
    forward_weight = azimuthal_weight_integral(theta_i_deg, constants) * DEG  # [rad]
    branch_weights = jnp.stack([forward_weight, 2.0 * jnp.pi - forward_weight])
    return jax.nn.logsumexp(terms, b=jnp.broadcast_to(branch_weights[:, None, None], terms.shape))


def _flat_batch(
    params, constants, *more
) -> tuple[tuple[int, ...], Params, HemisphereConstants, list]:
    """The parameters' fields, the constants' (a Δφ per draw,
    :func:`~brdf_infer.model.params.with_dphi_scale`) and ``more`` arrays as float64,
    broadcast to one batch shape and flattened: (batch shape, params, constants, more)."""
    fields = [jnp.asarray(value, float) for value in (*params, *constants, *more)]
    batch_shape = jnp.broadcast_shapes(*(value.shape for value in fields))
    flat = [jnp.broadcast_to(value, batch_shape).reshape(-1) for value in fields]
    count, terms = len(params), len(params) + len(constants)
    flat_params = Params(*flat[:count])
    return batch_shape, flat_params, HemisphereConstants(*flat[count:terms]), flat[terms:]


def _batched_log_tis(theta_i_deg, params, fold, constants, nodes):
    """ln TIS over a batch of parameter sets (:func:`_flat_batch`), at every θi."""
    theta_i = jnp.asarray(theta_i_deg, float)
    batch_shape, flat, flat_constants, _ = _flat_batch(params, constants)
    over_angles = jax.vmap(_log_tis_single, in_axes=(0, None, None, None, None))
    over_params = jax.vmap(over_angles, in_axes=(None, 0, None, 0, None))
    values = over_params(theta_i.reshape(-1), flat, fold, flat_constants, nodes)
    return values.reshape(batch_shape + theta_i.shape)


def log_tis_at(
    theta_i_deg: ArrayLike,
    params: Params,
    fold: bool = False,
    constants: HemisphereConstants = PAPER_CONSTANTS,
    nodes: int = TIS_NODES,
) -> jnp.ndarray:
    """ln TIS at one θi per parameter set: θi, the parameters' fields and the constants
    broadcast to one batch shape (where :func:`log_tis` evaluates every θi for every set).

    Returns:
        ln TIS [-], of the batch shape.
    """
    batch_shape, flat, flat_constants, (theta_i,) = _flat_batch(params, constants, theta_i_deg)
    single = jax.vmap(_log_tis_single, in_axes=(0, 0, None, 0, None))
    return single(theta_i, flat, fold, flat_constants, nodes).reshape(batch_shape)


@partial(jax.jit, static_argnames=("fold", "nodes"))
def log_tis(
    theta_i_deg: ArrayLike,
    params: Params,
    fold: bool = False,
    constants: HemisphereConstants = PAPER_CONSTANTS,
    nodes: int = TIS_NODES,
) -> jnp.ndarray:
    """ln TIS(θi): finite (with finite gradients) also where TIS overflows float64.

    Arguments and shapes as :func:`tis`.
    """
    return _batched_log_tis(theta_i_deg, params, fold, constants, nodes)


@partial(jax.jit, static_argnames=("fold", "nodes"))
def tis(
    theta_i_deg: ArrayLike,
    params: Params,
    fold: bool = False,
    constants: HemisphereConstants = PAPER_CONSTANTS,
    nodes: int = TIS_NODES,
) -> jnp.ndarray:
    """Total integrated scatter TIS(θi) of Eq. (9) for the BRDF of Eqs. (7), (8) (and (10)).

    Exact 1-D reduction with Gauss–Legendre panels split at the kinks; relative error below
    1e-10 for the published parameter sets at the default ``nodes``. A TIS above 1 means the
    parameters scatter more than the incident power (unphysical); see :func:`log_tis` where
    the value leaves the float64 range.

    Args:
        theta_i_deg: incidence angles θi [deg], any shape.
        params: ``Params``; fields may be arrays of one common (batch) shape, e.g. draws.
        fold: include the folding term of Eq. (10) (the article's Table 3 does; the
            default, the physical BRDF, gives the larger, conservative TIS).
        constants: Δφ and folding constants.
        nodes: Gauss–Legendre nodes per panel.

    Returns:
        TIS as a fraction, shape ``batch_shape + theta_i_deg.shape``.
    """
    return jnp.exp(_batched_log_tis(theta_i_deg, params, fold, constants, nodes))


def tis_with_error(
    theta_i_deg: ArrayLike,
    params: Params,
    fold: bool = False,
    constants: HemisphereConstants = PAPER_CONSTANTS,
    nodes: int = TIS_NODES,
) -> tuple[jnp.ndarray, jnp.ndarray]:
    """TIS and a conservative estimate of its absolute quadrature error.

    The estimate is |TIS(nodes) − TIS(nodes/2)|, the error of the coarser rule, which bounds
    the error of the returned finer one for this smooth-by-panel integrand.

    Returns:
        (tis, abs_error), both of the shape returned by :func:`tis`.
    """
    fine = tis(theta_i_deg, params, fold, constants, nodes)
    coarse = tis(theta_i_deg, params, fold, constants, max(nodes // 2, 2))
    return fine, jnp.abs(fine - coarse)
