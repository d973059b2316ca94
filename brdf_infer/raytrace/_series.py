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

import math
import time
from dataclasses import dataclass, replace

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer._sharding import gather_batch, shard_batch
from brdf_infer.measurements import Measurements
from brdf_infer.model import brdf_hemisphere, solid_angle
from brdf_infer.params import Params, params_to_dict
from brdf_infer.raytrace._trace import (
    ESTIMATORS,
    TALLIES,
    Setup,
    detector_images,
    tally_moments,
)
from brdf_infer.scene import RaytraceSettings, Scene

CHUNK_RAYS = 2**17  # rays per compiled call (memory ~ 100 MB)
BAND_QUANTILES = {"lo95": 0.025, "median": 0.5, "hi95": 0.975}
_INDEX = {name: k for k, name in enumerate(TALLIES)}


@dataclass(frozen=True)
class Configuration:
    """One detector position of the series [deg]."""

    theta_i_deg: float
    theta_s_deg: float
    measured: float
    measured_err: float

    @property
    def delta_deg(self) -> float:
        return self.theta_s_deg - self.theta_i_deg


@dataclass(frozen=True)
class Estimate:
    """Ray-traced quantities of one configuration (fractions of Pi) and their MC errors."""

    simulated: float
    mc_se: float
    image_ratio: float
    image_ratio_se: float
    detected_fraction: float | None


@dataclass(frozen=True)
class RaytraceResult:
    """A ray-traced series: one row per configuration (see :meth:`to_json`)."""

    rows: list[dict]
    rays: int
    warnings: list[str]
    estimator: str
    seed: int
    seconds: float
    compile_seconds: float

    def to_json(self) -> dict:
        return {
            "rows": self.rows,
            "rays": self.rays,
            "warnings": self.warnings,
            "estimator": self.estimator,
            "seed": self.seed,
            "seconds": self.seconds,
            "compile_seconds": self.compile_seconds,
        }


def build_setup(scene: Scene, settings: RaytraceSettings | None = None) -> tuple[Setup, int]:
    """The JAX setup of a scene's ``[raytrace]`` table and the limiting beam aperture.

    The limiting aperture (smallest angular radius seen from the source) is where ray
    directions are sampled; every ray must pass all apertures anyway.
    """
    settings = settings or scene.raytrace
    if settings is None:
        raise ValueError(f"scene '{scene.name}' has no [raytrace] table")
    detector = scene.series[settings.series]
    radii = np.array([d / 2 for d, _ in settings.beam_apertures_mm])
    distances = np.array([z for _, z in settings.beam_apertures_mm])
    setup = Setup(
        source_radius=jnp.asarray(settings.source_diameter_mm / 2),
        source_distance=jnp.asarray(settings.source_distance_mm),
        beam_aperture_radii=jnp.asarray(radii),
        beam_aperture_distances=jnp.asarray(distances),
        sample_half_size=jnp.asarray(settings.sample_size_mm) / 2,
        aperture_radius=jnp.asarray(detector.aperture_diameter_mm / 2),
        aperture_distance=jnp.asarray(detector.aperture_distance_mm),
        detector_behind=jnp.asarray(settings.detector_behind_aperture_mm),
        detector_half_size=jnp.asarray(settings.detector_size_mm) / 2,
        signal_half_size=jnp.asarray(settings.signal_region_mm) / 2,
    )
    return setup, int(np.argmin(radii / distances))


def with_aperture(scene: Scene, diameter_mm: float) -> Scene:
    """The scene with the ray-traced series' detector aperture diameter replaced."""
    name = scene.raytrace.series
    series = dict(scene.series)
    series[name] = replace(series[name], aperture_diameter_mm=float(diameter_mm))
    return replace(scene, series=series)


def configurations(scene: Scene, measurements: Measurements) -> list[Configuration]:
    """The (θi, θs) pairs measured in the ray-traced series, with the mean measured value."""
    series = scene.raytrace.series
    rows = measurements.series == series
    theta_i, theta_s = measurements.theta_i_deg[rows], measurements.theta_s_deg[rows]
    reflectance = measurements.reflectance[rows]
    error = (
        scene.errors.reflectance_rel * reflectance
        if measurements.reflectance_err is None
        else measurements.reflectance_err[rows]
    )
    result = []
    for pair in sorted(set(zip(theta_i.tolist(), theta_s.tolist(), strict=True))):
        same = (theta_i == pair[0]) & (theta_s == pair[1])
        result.append(
            Configuration(
                *pair,
                measured=float(reflectance[same].mean()),
                measured_err=float(np.sqrt(np.mean(error[same] ** 2))),
            )
        )
    return result


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


def point_estimate(configuration: Configuration, params: Params, scene: Scene) -> float:
    """BRDF·Ω·cos θs of Eq. (6) with the full-hemisphere BRDF in the forward plane."""
    brdf = brdf_hemisphere(
        configuration.theta_i_deg,
        configuration.theta_s_deg,
        180.0,
        params,
        scene.model.fold,
        scene.model.constants,
    )
    return float(brdf) * _aperture_factor(configuration, scene)


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
        estimates = [_estimate(s, o) for s, o in zip(sums, outer, strict=True)]
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
        row = {
            key_: (
                float(np.median([getattr(e, key_) for e in estimates]))
                if key_ != "detected_fraction"
                else _median_or_none([e.detected_fraction for e in estimates])
            )
            for key_ in Estimate.__dataclass_fields__
        }
        rows.append(
            {
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
        )
        log_simulated.append(np.log(np.maximum([e.simulated for e in estimates], 1e-300)))
    log_simulated = np.asarray(log_simulated)  # (configurations, draws)
    distance = np.sum((log_simulated - np.median(log_simulated, axis=1, keepdims=True)) ** 2, 0)
    best = int(np.argmin(distance))
    representative = Params(*(float(v[best]) for v in draws))
    seconds = time.perf_counter() - started
    result = RaytraceResult(rows, rays, _warnings(rows), "nee", seed, seconds, compile_seconds)
    return result, representative


def _median_or_none(values: list[float | None]) -> float | None:
    known = [v for v in values if v is not None]
    return float(np.median(known)) if known else None


def _aperture_factor(configuration: Configuration, scene: Scene) -> float:
    """Ω·cos θs of Eq. (6) for the ray-traced series' detector aperture."""
    detector = scene.series[scene.raytrace.series]
    omega = solid_angle(detector.aperture_diameter_mm, detector.aperture_distance_mm)
    return float(omega * np.cos(np.radians(configuration.theta_s_deg)))


def simulate_images(
    scene: Scene,
    measurements: Measurements,
    params: Params,
    rays: int = 2**18,
    seed: int = 0,
    bins: tuple[int, int] = (128, 32),
) -> dict:
    """Detector images at the scene's ``image_theta_i_deg`` for every detector angle measured
    there (Fig. 13): scattered and reference power per pixel, and the pixel edges [mm]."""
    setup, limiting = build_setup(scene)
    theta_i = scene.raytrace.image_theta_i_deg
    angles = sorted(
        {c.theta_s_deg for c in configurations(scene, measurements) if c.theta_i_deg == theta_i}
    ) or [theta_i]
    key = jax.random.PRNGKey(seed)
    images, reference = [], None
    for theta_s in angles:
        scattered, reference = detector_images(
            key,
            theta_i,
            theta_s,
            params,
            setup,
            scene.model.constants,
            rays,
            "nee",
            limiting,
            bins,
            scene.model.fold,
        )
        images.append(np.asarray(scattered))
    half = np.asarray(setup.detector_half_size)
    return {
        "theta_i_deg": theta_i,
        "theta_s_deg": angles,
        "scattered": np.stack(images),
        "reference": np.asarray(reference),
        "x_edges_mm": np.linspace(-half[0], half[0], bins[0] + 1),
        "y_edges_mm": np.linspace(-half[1], half[1], bins[1] + 1),
        "signal_half_size_mm": np.asarray(setup.signal_half_size),
    }


def thin_draws(draws: Params, count: int) -> Params:
    """``count`` draws spread evenly over all draws (all of them if there are fewer)."""
    total = int(np.size(draws.brdf0))
    index = np.unique(np.linspace(0, total - 1, min(count, total)).round().astype(int))
    return Params(*(np.asarray(v).reshape(-1)[index] for v in draws))


def _payload(scene: Scene, result: RaytraceResult, params: Params, source: str, draws) -> dict:
    return {
        **result.to_json(),
        "series": scene.raytrace.series,
        "params": params_to_dict(params),
        "params_source": source,
        "draws": draws,
        "scene_file": str(scene.path),
    }


def raytrace_payload(
    scene: Scene,
    measurements: Measurements,
    params: Params,
    source: str,
    rays: int | None = None,
    seed: int = 0,
    estimator: str = "nee",
    progress=None,
) -> dict:
    """:func:`raytrace_series` as the JSON object of ``brdf-infer raytrace --json``, with the
    parameters traced, where they came from (``source``) and the scene file."""
    result = raytrace_series(scene, measurements, params, rays, seed, estimator, progress)
    return _payload(scene, result, params, source, None)


def raytrace_posterior_payload(
    scene: Scene,
    measurements: Measurements,
    draws: Params,
    source: str,
    rays: int = 16_384,
    seed: int = 0,
    progress=None,
) -> dict:
    """:func:`raytrace_posterior` as the JSON object of ``brdf-infer raytrace --run``;
    ``params`` is the representative draw."""
    result, representative = raytrace_posterior(scene, measurements, draws, rays, seed, progress)
    return _payload(scene, result, representative, source, int(np.size(draws.brdf0)))
