"""brdf_infer: Bayesian BRDF and TIS inference for black coatings.

The reference problem is the Acktar Magic Black coating at Lyman-alpha (121.6 nm) from
Strumik et al. 2024, J. Astron. Telesc. Instrum. Syst. 10(1), 018004.

The model needs float64: its coefficients span 1e-13 to 1e-2 and its likelihood is evaluated
in log space, which float32 cannot carry. Importing the package changes no JAX setting and
installs no import hook (the modules that moved are listed in CHANGELOG.md);
:func:`use_float64` switches float64 on for the process, with JAX's persistent compilation
cache (``BRDF_INFER_CACHE=off`` to opt out). The command line calls it first; a library user
calls it before anything else, and the library's entry points (``load_scene``,
``run_posterior``, ``fit_lsq``, …) refuse float32 in one line (:class:`Float32Error`) rather
than switch a process-wide setting themselves.
"""

from importlib import import_module

from brdf_infer._internal.precision import Float32Error, use_float64
from brdf_infer._internal.resources import data_path
from brdf_infer.model.params import UV_PAPER, VIS_PAPER, Params

__version__ = "0.1.0"

# The entry points of the Python guide (docs/python.md), each where it lives; imported when
# first used, so that ``import brdf_infer`` loads no sampler, report or study
_ENTRY_POINTS = {
    "load_scene": "brdf_infer.scene",
    "check_instrument": "brdf_infer.scene",
    "run": "brdf_infer.workflow",
    "run_posterior": "brdf_infer.posterior",
    "fit_lsq": "brdf_infer.fit.lsq",
    "compare_families": "brdf_infer.studies.compare",
    "predict_rows": "brdf_infer.predict",
    "brdf_inplane": "brdf_infer.model",
    "brdf_hemisphere": "brdf_infer.model",
    "tis": "brdf_infer.model",
    "family": "brdf_infer.model",
}


def __getattr__(name: str):
    """An entry point of ``_ENTRY_POINTS``, from its module (PEP 562)."""
    if name in _ENTRY_POINTS:
        return getattr(import_module(_ENTRY_POINTS[name]), name)
    raise AttributeError(f"module 'brdf_infer' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)


__all__ = [
    "UV_PAPER",
    "VIS_PAPER",
    "Float32Error",
    "Params",
    "__version__",
    "data_path",
    "use_float64",
    *_ENTRY_POINTS,
]
