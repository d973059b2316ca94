"""brdf_infer: Bayesian BRDF and TIS inference for black coatings.

The reference problem is the Acktar Magic Black coating at Lyman-alpha (121.6 nm) from
Strumik et al. 2024, J. Astron. Telesc. Instrum. Syst. 10(1), 018004. Importing the package
switches JAX to float64: the model's coefficients span 1e-13 to 1e-2 and its likelihood is
evaluated in log space, which float32 cannot carry. It also turns on JAX's persistent
compilation cache (``brdf_infer._cache``; ``BRDF_INFER_CACHE=off`` to opt out).
"""

import jax

jax.config.update("jax_enable_x64", True)

from brdf_infer._cache import enable_compilation_cache  # noqa: E402
from brdf_infer._resources import data_path  # noqa: E402
from brdf_infer.params import UV_PAPER, VIS_PAPER, Params  # noqa: E402

enable_compilation_cache()

__version__ = "0.1.0"
__all__ = ["UV_PAPER", "VIS_PAPER", "Params", "__version__", "data_path"]
