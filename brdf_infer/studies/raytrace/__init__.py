"""Ray-tracing validation of the series II measurement setup (Sec. 6, Figs. 12–14)."""

from brdf_infer.runs.folder import DETECTOR_IMAGES_FILE, RAYTRACE_FILE
from brdf_infer.studies.raytrace._files import load_detector_images, load_traces, write_traces
from brdf_infer.studies.raytrace._images import simulate_images
from brdf_infer.studies.raytrace._payload import raytrace_payload, raytrace_posterior_payload
from brdf_infer.studies.raytrace._series import (
    RaytraceResult,
    raytrace_posterior,
    raytrace_series,
    thin_draws,
)
from brdf_infer.studies.raytrace._setup import (
    Configuration,
    build_setup,
    configurations,
    point_estimate,
    with_aperture,
)
from brdf_infer.studies.raytrace._tally import (
    CHUNK_RAYS,
    Estimate,
    compile_tallies,
    trace_configuration,
)
from brdf_infer.studies.raytrace._trace import ESTIMATORS, TALLIES, Setup

__all__ = [
    "CHUNK_RAYS",
    "DETECTOR_IMAGES_FILE",
    "ESTIMATORS",
    "RAYTRACE_FILE",
    "TALLIES",
    "Configuration",
    "Estimate",
    "RaytraceResult",
    "Setup",
    "build_setup",
    "compile_tallies",
    "configurations",
    "load_detector_images",
    "load_traces",
    "point_estimate",
    "raytrace_payload",
    "raytrace_posterior",
    "raytrace_posterior_payload",
    "raytrace_series",
    "simulate_images",
    "thin_draws",
    "trace_configuration",
    "with_aperture",
    "write_traces",
]
