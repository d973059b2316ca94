"""Ray-tracing validation of the series II measurement setup (Sec. 6, Figs. 12–14)."""

from brdf_infer.raytrace._series import (
    CHUNK_RAYS,
    Configuration,
    Estimate,
    RaytraceResult,
    build_setup,
    compile_tallies,
    configurations,
    point_estimate,
    raytrace_payload,
    raytrace_posterior,
    raytrace_posterior_payload,
    raytrace_series,
    simulate_images,
    thin_draws,
    trace_configuration,
    with_aperture,
)
from brdf_infer.raytrace._trace import ESTIMATORS, TALLIES, Setup

__all__ = [
    "CHUNK_RAYS",
    "ESTIMATORS",
    "TALLIES",
    "Configuration",
    "Estimate",
    "RaytraceResult",
    "Setup",
    "build_setup",
    "compile_tallies",
    "configurations",
    "point_estimate",
    "raytrace_payload",
    "raytrace_posterior",
    "raytrace_posterior_payload",
    "raytrace_series",
    "simulate_images",
    "thin_draws",
    "trace_configuration",
    "with_aperture",
]
