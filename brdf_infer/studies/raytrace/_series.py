"""Ray-traced raw reflectance of every configuration of a series (Sec. 6, Fig. 14).

Quantities per configuration (θi, θs = θi + δ), all fractions of the incident beam power Pi,
which the reference measurement (beam straight into the detector) supplies:

- ``simulated``: dPs/Pi, the power scattered through the detector aperture AD — the raw
  reflectance that Eq. (6) converts, with Ω of AD. For a vanishing AD it tends to the point
  estimate BRDF·Ω·cos θs; for the real AD it differs by the BRDF's variation over AD and by
  the part of the beam footprint the sample misses (θi = 80°).
- ``image_ratio``: the paper's image processing (Eq. 2): the scattered and the reference
  detector images summed over the same signal rectangle and divided. AD clips the reference
  beam, so this ratio is not dPs/Pi (README, "Ray tracing").
- ``detected_fraction``: the part of the power through AD that reaches the detector plane.

Each comes with its Monte Carlo standard error (ratio estimator, delta method); where no ray
reaches AD the value and its error are 0 and the result carries a warning.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer.model import brdf_hemisphere
from brdf_infer.model.params import Params
from brdf_infer.scene import Scene
from brdf_infer.studies.raytrace._setup import (
    Configuration,
    _aperture_factor,
    build_setup,
    configurations,
    point_estimate,
)
from brdf_infer.studies.raytrace._tally import (
    Estimate,
    _chunks,
    _estimate,
    _group_size,
    _over_draws,
    _trace_group,
    compile_tallies,
)
from brdf_infer.studies.raytrace._trace import ESTIMATORS, Setup
from brdf_infer.tables.measurements import Measurements

BAND_QUANTILES = {"lo95": 0.025, "median": 0.5, "hi95": 0.975}


@dataclass(frozen=True)
class RaytraceResult:
    """A ray-traced series: one row per configuration (see :meth:`as_json`)."""

    rows: list[dict]
    rays: int
    warnings: list[str]
    estimator: str
    seed: int
    seconds: float
    compile_seconds: float

    def as_json(self) -> dict:
        return {
            "rows": self.rows,
            "rays": self.rays,
            "warnings": self.warnings,
            "estimator": self.estimator,
            "seed": self.seed,
            "seconds": self.seconds,
            "compile_seconds": self.compile_seconds,
        }


def _row(configuration: Configuration, estimate: Estimate, point: float) -> dict:
    return {
        "theta_i_deg": configuration.theta_i_deg,
        "delta_deg": configuration.delta_deg,
        "theta_s_deg": configuration.theta_s_deg,
        "simulated": estimate.simulated,
        "mc_se": estimate.mc_se,
        "measured": configuration.measured,
        "measured_err": configuration.measured_err,
        "point_estimate": point,
        "image_ratio": estimate.image_ratio,
        "image_ratio_se": estimate.image_ratio_se,
        "detected_fraction": estimate.detected_fraction,
    }


def _warnings(rows: list[dict]) -> list[str]:
    missed = [f"{r['theta_i_deg']:g}/{r['delta_deg']:+g}" for r in rows if r["simulated"] == 0]
    if not missed:
        return []
    return [
        f"no ray reached the detector aperture at θi/δ = {', '.join(missed)} deg: "
        "increase the rays or use the nee estimator"
    ]


def _announce(progress, configuration: Configuration, rays: int, what: str = "") -> None:
    if progress:
        progress(
            f"ray tracing θi = {configuration.theta_i_deg:g}°, "
            f"θs = {configuration.theta_s_deg:g}° ({rays} rays{what})"
        )


def raytrace_series(
    scene: Scene,
    measurements: Measurements,
    params: Params,
    rays: int | None = None,
    seed: int = 0,
    estimator: str = "nee",
    progress=None,
) -> RaytraceResult:
    """Ray-trace every configuration of the scene's ``[raytrace]`` series (Sec. 6, Fig. 14).

    Args:
        scene: a scene with a ``[raytrace]`` table.
        measurements: its measurements (the configurations and measured values).
        params: the parameters traced (paper units).
        rays: rays per configuration (default the scene's ``raytrace.rays``).
        seed: random seed; each configuration uses its own stream derived from it.
        estimator: ``"nee"`` (next-event estimation) or ``"naive"`` (forward ray trace).
        progress: optional callable taking a message per configuration.

    Returns:
        A :class:`RaytraceResult`; rows hold ``theta_i_deg``, ``delta_deg``, ``theta_s_deg``,
        ``simulated``, ``mc_se``, ``measured``, ``measured_err``, ``point_estimate``,
        ``image_ratio``, ``image_ratio_se`` and ``detected_fraction``.
    """
    rays = rays or scene.raytrace.rays
    if estimator not in ESTIMATORS:
        raise ValueError(f"unknown estimator {estimator!r} (known: {', '.join(ESTIMATORS)})")
    setup, limiting = build_setup(scene)
    constants = scene.model.constants
    fold = scene.model.fold
    measured = configurations(scene, measurements)
    group = _group_size(len(measured))
    compile_seconds = compile_tallies(
        params, setup, constants, rays, estimator, limiting, False, fold, group
    )
    key = jax.random.PRNGKey(seed)
    started = time.perf_counter()
    rows = []
    for first in range(0, len(measured), group):
        part = measured[first : first + group]
        for configuration in part:
            _announce(progress, configuration, rays)
        streams = [jax.random.fold_in(key, first + k) for k in range(len(part))]
        estimates = _trace_group(
            part, streams, params, setup, limiting, constants, rays, estimator, fold, group
        )
        for configuration, estimate in zip(part, estimates, strict=True):
            rows.append(_row(configuration, estimate, point_estimate(configuration, params, scene)))
    seconds = time.perf_counter() - started
    return RaytraceResult(rows, rays, _warnings(rows), estimator, seed, seconds, compile_seconds)


def raytrace_posterior(
    scene: Scene,
    measurements: Measurements,
    draws: Params,
    rays: int = 16_384,
    seed: int = 0,
    progress=None,
) -> tuple[RaytraceResult, Params]:
    """Ray-trace every configuration for each posterior draw (NEE, common random numbers).

    Rows hold the median over the draws of every quantity of :func:`raytrace_series` (the
    MC error is the median per-draw error) and ``band``: the 2.5 %, 50 % and 97.5 %
    quantiles of ``simulated``. Per-parameter medians are not used: for correlated
    parameters they are not a typical draw.

    Returns:
        The result and the representative draw: the one whose simulated series is closest
        (in log) to the medians, e.g. for detector images.
    """
    setup, limiting = build_setup(scene)
    constants = scene.model.constants
    count = int(np.size(draws.brdf0))
    draws = Params(*(jnp.asarray(np.asarray(v, float).reshape(-1)) for v in draws))
    fold = scene.model.fold
    compile_seconds = compile_tallies(
        Params(*(v[:16] for v in draws)), setup, constants, rays, "nee", limiting, True, fold
    )
    key = jax.random.PRNGKey(seed)
    started = time.perf_counter()
    rows, log_simulated = [], []
    for index, configuration in enumerate(configurations(scene, measurements)):
        _announce(progress, configuration, rays, f" x {count} draws")
        stream = jax.random.fold_in(key, index)
        estimates = _trace_draws(
            configuration, stream, draws, count, setup, limiting, constants, rays, fold
        )
        points = np.asarray(
            brdf_hemisphere(
                configuration.theta_i_deg,
                configuration.theta_s_deg,
                180.0,
                draws,
                fold,
                constants,
            )
        ) * _aperture_factor(configuration, scene)
        rows.append(_posterior_row(configuration, estimates, points))
        log_simulated.append(np.log(np.maximum([e.simulated for e in estimates], 1e-300)))
    representative = _representative(draws, log_simulated)
    seconds = time.perf_counter() - started
    result = RaytraceResult(rows, rays, _warnings(rows), "nee", seed, seconds, compile_seconds)
    return result, representative


def _trace_draws(
    configuration: Configuration,
    stream: jax.Array,
    draws: Params,
    count: int,
    setup: Setup,
    limiting: int,
    constants,
    rays: int,
    fold: bool,
) -> list[Estimate]:
    """One configuration for each of ``count`` draws (flat arrays), 16 draws per compiled call,
    every draw with the same random stream (common random numbers)."""
    sums, outer = 0.0, 0.0
    for chunk, n in enumerate(_chunks(rays)):
        parts = [
            _over_draws(
                jax.random.fold_in(stream, chunk),
                configuration.theta_i_deg,
                configuration.theta_s_deg,
                Params(*(v[start : start + 16] for v in draws)),
                setup,
                constants,
                n,
                "nee",
                limiting,
                fold,
            )
            for start in range(0, count, 16)
        ]
        sums = sums + np.concatenate([np.asarray(p[0]) for p in parts])
        outer = outer + np.concatenate([np.asarray(p[1]) for p in parts])
    return [_estimate(s, o) for s, o in zip(sums, outer, strict=True)]


def _posterior_row(
    configuration: Configuration, estimates: list[Estimate], points: np.ndarray
) -> dict:
    """The row of one configuration: medians over the draws of each estimate and of the point
    estimates ``points``, and the band of ``simulated``."""
    row = {
        key_: (
            float(np.median([getattr(e, key_) for e in estimates]))
            if key_ != "detected_fraction"
            else _median_or_none([e.detected_fraction for e in estimates])
        )
        for key_ in Estimate.__dataclass_fields__
    }
    return {
        **_row(configuration, Estimate(**row), float(np.median(points))),
        "band": dict(
            zip(
                BAND_QUANTILES,
                np.quantile(
                    [e.simulated for e in estimates], list(BAND_QUANTILES.values())
                ).tolist(),
                strict=True,
            )
        ),
    }


def _representative(draws: Params, log_simulated: list[np.ndarray]) -> Params:
    """The draw whose ln(simulated) over the configurations is closest to their medians."""
    log_simulated = np.asarray(log_simulated)  # (configurations, draws)
    distance = np.sum((log_simulated - np.median(log_simulated, axis=1, keepdims=True)) ** 2, 0)
    best = int(np.argmin(distance))
    return Params(*(float(v[best]) for v in draws))


def _median_or_none(values: list[float | None]) -> float | None:
    known = [v for v in values if v is not None]
    return float(np.median(known)) if known else None


def thin_draws(draws: Params, count: int) -> Params:
    """``count`` draws spread evenly over all draws (all of them if there are fewer)."""
    total = int(np.size(draws.brdf0))
    index = np.unique(np.linspace(0, total - 1, min(count, total)).round().astype(int))
    return Params(*(np.asarray(v).reshape(-1)[index] for v in draws))
