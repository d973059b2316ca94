"""Root pytest configuration, read before any test module imports brdf_infer.

The notebooks run in the test suite with fewer NUTS draws, and the suite's compiled programs
go to a persistent cache of its own (not the user's), which later runs reuse.
"""

import os
from pathlib import Path

# 2000 draws after 500 warmup iterations, as the suite's other lya runs (tests/helpers.py,
# REDUCED_NUTS): the notebooks' NUTS program comes from the cache, and the Lyman-alpha
# notebook's 4 chains reach the tail ESS its verdict asks for (4 x 1000 draws may not on some CPUs)
os.environ.setdefault("BRDF_INFER_NOTEBOOK_DRAWS", "2000")
os.environ.setdefault("BRDF_INFER_NOTEBOOK_WARMUP", "500")
os.environ.setdefault(
    "BRDF_INFER_CACHE", str(Path(__file__).parent / ".pytest_cache" / "brdf_infer_jax")
)
