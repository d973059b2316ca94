"""The forward models: Strumik et al. 2024, Eqs. (6)–(10), and the ray tracers' scatter lobes
(ABg, Harvey–Shack, Lambertian) behind one family interface, in JAX, angles in degrees.

Every function is pure and float64, and goes through ``jit``, ``vmap`` and ``grad``. Eq. (10)'s
folding (a measurement artefact, Sec. 5) is off unless ``fold=True`` is passed: the physical BRDF
and its TIS are the defaults.

Beside the forward models, the package holds the rest of the statistical model, one module each
(none of them is imported here): ``params`` the parameters of Eq. (7) in paper units and the
constants of Eqs. (8) and (10), ``coordinates`` their well-conditioned internal coordinates,
``priors`` the priors on those coordinates, and ``error_model`` how a measured ln R scatters
about the prediction. ``brdf_infer.predict`` puts them together into the prediction of each row.
"""

from brdf_infer.model._aperture import (
    brdf_to_reflectance,
    log_aperture_factor,
    reflectance_to_brdf,
    solid_angle,
)
from brdf_infer.model._energy import (
    BOUND_GAP,
    ENERGY_MAP_SOFTNESS,
    ENERGY_MARGIN,
    ENERGY_THETA_I_DEG,
    below_bound,
    conserves_energy,
    energy_log_factor,
    log_brdf0_bound,
    max_log_tis,
)
from brdf_infer.model._families import (
    FAMILIES,
    FAMILY_NAMES,
    REFERENCE_FAMILY,
    Coordinate,
    ModelFamily,
    Physical,
    check_family_name,
    family,
    run_family_name,
    strumik_family,
)
from brdf_infer.model._hemisphere import (
    azimuthal_half_width,
    azimuthal_weight,
    azimuthal_weight_integral,
    brdf_hemisphere,
    log_brdf_hemisphere,
)
from brdf_infer.model._inplane import (
    brdf_inplane,
    fold_statement,
    log_brdf_inplane,
    log_fold,
    positive_power,
)
from brdf_infer.model._lobes import (
    CHECK_QUADRATURE,
    FIT_QUADRATURE,
    PRECISE_QUADRATURE,
    Quadrature,
    abg_integral,
    abg_log_bsdf,
    beta_distance,
    disk_integral,
    harvey_shack_integral,
    harvey_shack_log_bsdf,
)
from brdf_infer.model._tis import TIS_NODES, log_tis, tis, tis_with_error

__all__ = [
    "BOUND_GAP",
    "CHECK_QUADRATURE",
    "ENERGY_MAP_SOFTNESS",
    "ENERGY_MARGIN",
    "ENERGY_THETA_I_DEG",
    "FAMILIES",
    "FAMILY_NAMES",
    "FIT_QUADRATURE",
    "PRECISE_QUADRATURE",
    "REFERENCE_FAMILY",
    "TIS_NODES",
    "Coordinate",
    "ModelFamily",
    "Physical",
    "Quadrature",
    "abg_integral",
    "abg_log_bsdf",
    "azimuthal_half_width",
    "azimuthal_weight",
    "azimuthal_weight_integral",
    "below_bound",
    "beta_distance",
    "brdf_hemisphere",
    "brdf_inplane",
    "brdf_to_reflectance",
    "check_family_name",
    "conserves_energy",
    "disk_integral",
    "energy_log_factor",
    "family",
    "fold_statement",
    "harvey_shack_integral",
    "harvey_shack_log_bsdf",
    "log_aperture_factor",
    "log_brdf0_bound",
    "log_brdf_hemisphere",
    "log_brdf_inplane",
    "log_fold",
    "log_tis",
    "max_log_tis",
    "positive_power",
    "reflectance_to_brdf",
    "run_family_name",
    "solid_angle",
    "strumik_family",
    "tis",
    "tis_with_error",
]
