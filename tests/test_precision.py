"""float64 is required; float32 is refused with a clear message."""

import jax
import pytest

from brdf_infer._precision import Float32Error, require_float64
from tests.helpers import run_cli


def test_float32_is_refused(capsys):
    jax.config.update("jax_enable_x64", False)
    try:
        with pytest.raises(Float32Error, match="float64"):
            require_float64()
        code, _, err = run_cli("tis", capsys=capsys)
        assert code == 2 and "float32" in err
    finally:
        jax.config.update("jax_enable_x64", True)
    require_float64()
