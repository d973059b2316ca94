"""The series II setup of a scene's ``[raytrace]`` table (Sec. 6, Fig. 12): its lengths as a
JAX pytree, the configurations measured, and the Eq. (6) point estimate at each."""

from __future__ import annotations

from dataclasses import dataclass, replace

import jax.numpy as jnp
import numpy as np

from brdf_infer.model import brdf_hemisphere, solid_angle
from brdf_infer.model.params import Params
from brdf_infer.scene import RaytraceSettings, Scene
from brdf_infer.studies.raytrace._trace import Setup
from brdf_infer.tables.measurements import Measurements


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


def _aperture_factor(configuration: Configuration, scene: Scene) -> float:
    """Ω·cos θs of Eq. (6) for the ray-traced series' detector aperture."""
    detector = scene.series[scene.raytrace.series]
    omega = solid_angle(detector.aperture_diameter_mm, detector.aperture_distance_mm)
    return float(omega * np.cos(np.radians(configuration.theta_s_deg)))
