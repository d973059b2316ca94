"""Monte Carlo estimates of one configuration from the per-ray tallies of :mod:`._trace`:
ratio estimators with their delta-method errors, rays traced in chunks of ``CHUNK_RAYS`` by
programs compiled once, vmapped over parameter draws or over configurations."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer._internal.sharding import gather_batch, shard_batch
from brdf_infer.model.params import Params
from brdf_infer.studies.raytrace._setup import Configuration
from brdf_infer.studies.raytrace._trace import ESTIMATORS, TALLIES, Setup, tally_moments

CHUNK_RAYS = 2**17  # rays per compiled call (memory ~ 100 MB)


_INDEX = {name: k for k, name in enumerate(TALLIES)}


@dataclass(frozen=True)
class Estimate:
    """Ray-traced quantities of one configuration (fractions of Pi) and their MC errors."""

    simulated: float
    mc_se: float
    image_ratio: float
    image_ratio_se: float
    detected_fraction: float | None


def _ratio(sums: np.ndarray, outer: np.ndarray, top: str, bottom: str) -> tuple[float, float]:
    """Σtop/Σbottom and its standard error by the delta method."""
    i, j = _INDEX[top], _INDEX[bottom]
    if sums[j] <= 0:
        return 0.0, 0.0
    ratio = sums[i] / sums[j]
    variance = (outer[i, i] - 2 * ratio * outer[i, j] + ratio**2 * outer[j, j]) / sums[j] ** 2
    return float(ratio), float(math.sqrt(max(variance, 0.0)))


def _estimate(sums: np.ndarray, outer: np.ndarray) -> Estimate:
    simulated, se = _ratio(sums, outer, "aperture", "beam")
    image_ratio, image_se = _ratio(sums, outer, "signal", "reference_signal")
    through = sums[_INDEX["aperture"]]
    detected = float(sums[_INDEX["detector"]] / through) if through > 0 else None
    return Estimate(simulated, se, image_ratio, image_se, detected)


def _chunks(rays: int) -> list[int]:
    full, rest = divmod(rays, CHUNK_RAYS)
    return [CHUNK_RAYS] * full + ([rest] if rest else [])


def trace_configuration(
    configuration: Configuration,
    params: Params,
    setup: Setup,
    limiting: int,
    constants,
    rays: int,
    key: jax.Array,
    estimator: str = "nee",
    fold: bool = False,
) -> Estimate:
    """Ray-trace one configuration with ``rays`` rays in chunks of ``CHUNK_RAYS`` (Eq. 10's
    folding when ``fold``)."""
    if estimator not in ESTIMATORS:
        raise ValueError(f"unknown estimator {estimator!r} (known: {', '.join(ESTIMATORS)})")
    sums, outer = np.zeros(len(TALLIES)), np.zeros((len(TALLIES), len(TALLIES)))
    for index, n in enumerate(_chunks(rays)):
        chunk_sums, chunk_outer = tally_moments(
            jax.random.fold_in(key, index),
            configuration.theta_i_deg,
            configuration.theta_s_deg,
            params,
            setup,
            constants,
            n,
            estimator,
            limiting,
            fold,
        )
        sums += np.asarray(chunk_sums)
        outer += np.asarray(chunk_outer)
    return _estimate(sums, outer)


def compile_tallies(
    params: Params,
    setup,
    constants,
    rays: int,
    estimator,
    limiting,
    batched: bool,
    fold=False,
    group: int = 0,
):
    """Compile every chunk size once, outside the timing; returns the seconds it took.

    ``batched``: the program vmapped over parameter draws; ``group`` > 0: the program
    vmapped over that many configurations (:func:`raytrace_series`)."""
    started = time.perf_counter()
    key = jax.random.PRNGKey(0)
    for n in sorted(set(_chunks(rays))):
        if group:
            keys = jnp.stack([key] * group)
            angles = jnp.full(group, 45.0)
            arguments = shard_batch((keys, angles, angles))
            result = _over_configurations(
                *arguments, params, setup, constants, n, estimator, limiting, fold
            )
        else:
            function = _over_draws if batched else tally_moments
            result = function(
                key, 45.0, 45.0, params, setup, constants, n, estimator, limiting, fold
            )
        jax.block_until_ready(result)
    return time.perf_counter() - started


_over_draws = jax.jit(
    jax.vmap(tally_moments, in_axes=(None, None, None, 0, None, None, None, None, None, None)),
    static_argnums=(6, 7, 8, 9),
)


# the configuration axis: one program for a group of (key, θi, θs), sharded over the devices
_over_configurations = jax.jit(
    jax.vmap(tally_moments, in_axes=(0, 0, 0, None, None, None, None, None, None, None)),
    static_argnums=(6, 7, 8, 9),
)


RAYS_PER_CALL = 2**19  # rays in flight per call on a CPU (memory ~ 400 MB)


def _group_size(configurations: int) -> int:
    """Configurations traced together: all of them on an accelerator or several devices,
    else as many as keep ``RAYS_PER_CALL`` rays in flight."""
    devices = jax.device_count()
    if jax.default_backend() != "cpu" or devices > 1:
        return max(configurations, 1)
    return max(1, min(configurations, RAYS_PER_CALL // CHUNK_RAYS))


def _trace_group(
    part: list[Configuration],
    streams: list,
    params: Params,
    setup: Setup,
    limiting: int,
    constants,
    rays: int,
    estimator: str,
    fold: bool,
    group: int,
) -> list[Estimate]:
    """Ray-trace up to ``group`` configurations in one vmapped call per chunk, their axis
    sharded over every device (``shard_batch``); each configuration's stream is the one
    :func:`trace_configuration` would use, so the estimates are those of tracing each
    configuration alone (to rounding)."""
    count = len(part)
    pad = group - count
    theta_i = np.array([c.theta_i_deg for c in part] + [part[-1].theta_i_deg] * pad)
    theta_s = np.array([c.theta_s_deg for c in part] + [part[-1].theta_s_deg] * pad)
    sums = np.zeros((count, len(TALLIES)))
    outer = np.zeros((count, len(TALLIES), len(TALLIES)))
    for chunk, n in enumerate(_chunks(rays)):
        keys = [jax.random.fold_in(stream, chunk) for stream in streams]
        keys = jnp.stack(keys + [keys[-1]] * pad)
        arguments = shard_batch((keys, jnp.asarray(theta_i), jnp.asarray(theta_s)))
        chunk_sums, chunk_outer = gather_batch(
            _over_configurations(*arguments, params, setup, constants, n, estimator, limiting, fold)
        )
        sums += np.asarray(chunk_sums)[:count]
        outer += np.asarray(chunk_outer)[:count]
    return [_estimate(s, o) for s, o in zip(sums, outer, strict=True)]
