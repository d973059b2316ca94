"""The measurement kernel: each row's prediction as a weighted sum of BRDF values.

For the ``aperture`` and ``image`` instruments (:mod:`brdf_infer.instrument._geometry`) the
nodes of a row come from a scrambled Sobol cubature of ``candidates`` points over the source
disk, the limiting beam aperture and the detector aperture. That is too many to evaluate in
every likelihood call, so they are compressed to a few nodes per row: the nodes with weight
are binned on weighted-quantile edges of θi, θ and |φ − 180°| (Eq. 8's azimuthal weight is
linear in |φ − 180°|, so the cusp of the forward plane lies on a bin edge, not inside a bin),
and each bin becomes one node at the weighted mean of its angles, carrying the bin's total
weight. The mean of a bin is exact for any BRDF linear over it; the error is second order in
the bin width (benchmark: ≲ 0.1 % at 16 nodes per row against the full cubature, which agrees
with the ray tracer within its Monte Carlo error).

The predicted raw reflectance of a row is then Σ_k w_k BRDF(θi_k, θ_k, φ_k): a fixed-shape
weighted log-sum-exp that ``jit``, ``grad`` and NUTS go through, whatever the BRDF family.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer.instrument._geometry import BeamGeometry, measurement_nodes, sobol_uniforms

INSTRUMENT_MODELS: tuple[str, ...] = ("point", "aperture", "image")
# nodes per row → bins in (θi, θ, |φ − 180°|)
NODE_SHAPES: dict[int, tuple[int, int, int]] = {
    8: (1, 4, 2),
    16: (1, 8, 2),
    32: (2, 8, 2),
    64: (2, 8, 4),
    128: (2, 16, 4),
}
KERNEL_NODES = 16
# Sobol points of the full cubature: the image ratio counts only the ≈ 9 % of them that land in
# the signal square (and divides by the reference beam's part in it), so it needs more to
# reach the same accuracy (0.5-0.8 % at 2^16, ≲ 0.1 % at 2^18; benchmark).
DEFAULT_CANDIDATES = {"aperture": 2**16, "image": 2**18}


class Kernel(NamedTuple):
    """Compressed nodes of every row (a pytree; arrays of shape (rows, nodes)).

    Attributes:
        theta_i_deg: local incidence angle [deg].
        theta_deg: polar scattering angle [deg].
        phi_deg: azimuth, forward plane at 180° [deg].
        weight: w_k [sr]: the row's prediction is Σ_k w_k BRDF_k.
        applies: (rows,) 1 where the row is predicted through the kernel, 0 where Eq. (6)
            or the BRDF itself stays (rows of a ``brdf`` series).
    """

    theta_i_deg: jnp.ndarray
    theta_deg: jnp.ndarray
    phi_deg: jnp.ndarray
    weight: jnp.ndarray
    applies: jnp.ndarray


def _weighted_inner_edges(values: np.ndarray, weights: np.ndarray, bins: int) -> np.ndarray:
    order = np.argsort(values, kind="stable")
    cumulative = np.cumsum(weights[order])
    cumulative /= cumulative[-1]
    index = np.searchsorted(cumulative, np.linspace(0.0, 1.0, bins + 1)[1:-1])
    return values[order][np.minimum(index, values.size - 1)]


def compress_nodes(
    theta_i_deg: np.ndarray,
    theta_deg: np.ndarray,
    phi_deg: np.ndarray,
    weight: np.ndarray,
    shape: tuple[int, int, int],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Bin weighted nodes into ``shape`` = (θi, θ, |φ − 180°|) bins (module docstring).

    Returns:
        θi, θ, φ [deg] and weight of prod(shape) nodes; empty bins carry weight 0 at the
        weighted mean of all nodes (a valid angle, so no NaN enters a gradient).
    """
    keep = weight > 0
    count = int(np.prod(shape))
    if not keep.any():
        return (np.full(count, 45.0), np.full(count, 45.0), np.full(count, 180.0), np.zeros(count))
    distance = np.abs(np.mod(phi_deg[keep], 360.0) - 180.0)
    coordinates = (theta_i_deg[keep], theta_deg[keep], distance)
    w = weight[keep]
    cell = np.zeros(w.size, dtype=int)
    for values, bins in zip(coordinates, shape, strict=True):
        edges = _weighted_inner_edges(values, w, bins)
        cell = cell * bins + np.searchsorted(edges, values, side="right")
    total = np.bincount(cell, w, count)
    filled = total > 0
    safe = np.where(filled, total, 1.0)
    means = []
    for values in coordinates:
        overall = np.sum(w * values) / np.sum(w)
        means.append(np.where(filled, np.bincount(cell, w * values, count) / safe, overall))
    return means[0], means[1], 180.0 - means[2], total


@functools.lru_cache(maxsize=256)
def _row_kernel(
    theta_i_deg: float,
    theta_s_deg: float,
    geometry: BeamGeometry,
    instrument: str,
    nodes: int,
    candidates: int,
) -> tuple[np.ndarray, ...]:
    full = measurement_nodes(theta_i_deg, theta_s_deg, geometry, _uniforms(candidates))
    weight = full.aperture_weight if instrument == "aperture" else full.image_weight
    return compress_nodes(
        full.theta_i_deg, full.theta_deg, full.phi_deg, weight, NODE_SHAPES[nodes]
    )


def clear_row_kernel_cache() -> None:
    """Forget the row kernels built so far (a benchmark times the build, not the cache)."""
    _row_kernel.cache_clear()


@functools.lru_cache(maxsize=4)
def _uniforms(candidates: int) -> np.ndarray:
    return sobol_uniforms(candidates)


def row_kernels(
    theta_i_deg: np.ndarray,
    theta_s_deg: np.ndarray,
    geometries: list[BeamGeometry | None],
    instrument: str,
    nodes: int = KERNEL_NODES,
    candidates: int | None = None,
) -> Kernel:
    """The kernel of rows at nominal (θi, θs) [deg]; a row whose geometry is None keeps its
    own prediction (``applies`` 0; one node at its nominal angles, weight 1). ``candidates``:
    Sobol points of the full cubature (default :data:`DEFAULT_CANDIDATES` of the instrument).

    Raises:
        ValueError: unknown instrument or node count.
    """
    if instrument not in INSTRUMENT_MODELS[1:]:
        raise ValueError(f"no kernel for instrument {instrument!r}")
    if nodes not in NODE_SHAPES:
        raise ValueError(f"nodes must be one of {sorted(NODE_SHAPES)}, got {nodes}")
    candidates = candidates or DEFAULT_CANDIDATES[instrument]
    parts, applies = [], []
    for ti, ts, geometry in zip(theta_i_deg, theta_s_deg, geometries, strict=True):
        if geometry is None:
            nominal = (
                np.full(nodes, float(ti)),
                np.full(nodes, abs(float(ts))),
                np.full(nodes, 180.0 if ts >= 0 else 0.0),
                np.eye(1, nodes).ravel(),
            )
            parts.append(nominal)
            applies.append(0.0)
            continue
        parts.append(_row_kernel(float(ti), float(ts), geometry, instrument, nodes, candidates))
        applies.append(1.0)
    stacked = [jnp.asarray(np.stack([p[k] for p in parts])) for k in range(4)]
    return Kernel(*stacked, applies=jnp.asarray(applies))


def kernel_log_reflectance(
    log_brdf: Callable[[jnp.ndarray, jnp.ndarray, jnp.ndarray], jnp.ndarray], kernel: Kernel
) -> jnp.ndarray:
    """ln Σ_k w_k BRDF(θi_k, θ_k, φ_k) of every row, given ``log_brdf(θi, θ, φ)`` [ln sr⁻¹]
    (a weighted log-sum-exp: finite where single nodes under- or overflow)."""
    values = log_brdf(kernel.theta_i_deg, kernel.theta_deg, kernel.phi_deg)
    return jax.nn.logsumexp(values, axis=-1, b=kernel.weight)
