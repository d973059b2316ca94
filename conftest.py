"""Root pytest configuration, read before any test module imports brdf_infer.

The notebooks run in the test suite with fewer NUTS draws, and the suite's compiled programs
go to a persistent cache of its own (not the user's), which later runs reuse.
"""

import os
from pathlib import Path

# 500 draws after 500 warmup iterations: the warmup of the suite's other lya runs
# (tests/helpers.py, SUITE_WARMUP), so the notebook's NUTS program comes from the cache
os.environ.setdefault("BRDF_INFER_NOTEBOOK_DRAWS", "500")
os.environ.setdefault(
    "BRDF_INFER_CACHE", str(Path(__file__).parent / ".pytest_cache" / "brdf_infer_jax")
)
