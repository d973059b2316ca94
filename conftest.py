"""Root pytest configuration, read before any test module imports brdf_infer.

The notebooks run in the test suite with few NUTS draws, and the suite's compiled programs
go to a persistent cache of its own (not the user's), which later runs reuse.
"""

import os
from pathlib import Path

os.environ.setdefault("BRDF_INFER_NOTEBOOK_DRAWS", "150")
os.environ.setdefault(
    "BRDF_INFER_CACHE", str(Path(__file__).parent / ".pytest_cache" / "brdf_infer_jax")
)
