"""The instrument function: what a measured raw reflectance is, as a function of the BRDF.

``point`` is Eq. (6) (BRDF·Ω·cos θs at the nominal angles, the article's conversion);
``aperture`` and ``image`` average the BRDF over the beam footprint and the detector aperture
(:mod:`brdf_infer.instrument._geometry`) through a precomputed kernel
(:mod:`brdf_infer.instrument._kernel`).
"""

from __future__ import annotations

from brdf_infer.instrument._geometry import (
    BeamGeometry,
    Nodes,
    measurement_nodes,
    sobol_uniforms,
)
from brdf_infer.instrument._kernel import (
    DEFAULT_CANDIDATES,
    INSTRUMENT_MODELS,
    KERNEL_NODES,
    NODE_SHAPES,
    Kernel,
    clear_row_kernel_cache,
    compress_nodes,
    kernel_log_reflectance,
    row_kernels,
)
from brdf_infer.instrument._scene import beam_geometry, build_kernel

__all__ = [
    "DEFAULT_CANDIDATES",
    "INSTRUMENT_MODELS",
    "KERNEL_NODES",
    "NODE_SHAPES",
    "BeamGeometry",
    "Kernel",
    "Nodes",
    "beam_geometry",
    "build_kernel",
    "clear_row_kernel_cache",
    "compress_nodes",
    "kernel_log_reflectance",
    "measurement_nodes",
    "row_kernels",
    "sobol_uniforms",
]
