"""Root pytest configuration: the notebooks run in the test suite with few NUTS draws."""

import os

os.environ.setdefault("BRDF_INFER_NOTEBOOK_DRAWS", "150")
