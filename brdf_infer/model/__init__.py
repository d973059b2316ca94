"""The forward model of Strumik et al. 2024: Eqs. (6)–(10), in JAX, angles in degrees.

Every function is pure and float64, and goes through ``jit``, ``vmap`` and ``grad``.
"""

from brdf_infer.model._aperture import (
    brdf_to_reflectance,
    log_aperture_factor,
    reflectance_to_brdf,
    solid_angle,
)
from brdf_infer.model._hemisphere import (
    azimuthal_half_width,
    azimuthal_weight,
    azimuthal_weight_integral,
    brdf_hemisphere,
    log_brdf_hemisphere,
)
from brdf_infer.model._inplane import brdf_inplane, log_brdf_inplane, log_fold, positive_power
from brdf_infer.model._tis import DEFAULT_NODES, log_tis, tis, tis_with_error

__all__ = [
    "DEFAULT_NODES",
    "azimuthal_half_width",
    "azimuthal_weight",
    "azimuthal_weight_integral",
    "brdf_hemisphere",
    "brdf_inplane",
    "brdf_to_reflectance",
    "log_aperture_factor",
    "log_brdf_hemisphere",
    "log_brdf_inplane",
    "log_fold",
    "log_tis",
    "positive_power",
    "reflectance_to_brdf",
    "solid_angle",
    "tis",
    "tis_with_error",
]
