"""float64 guard: the model is stiff (a2 ~ 1e-11) and lives in log space."""

from __future__ import annotations

import jax.numpy as jnp


class Float32Error(RuntimeError):
    """JAX runs in float32, which cannot carry this model."""


def require_float64() -> None:
    """Refuse to run when JAX's default float is float32.

    Raises:
        Float32Error: if ``jax_enable_x64`` was switched off after importing brdf_infer.
    """
    if jnp.asarray(1.0).dtype != jnp.float64:
        raise Float32Error(
            "JAX runs in float32; brdf_infer needs float64 "
            "(jax.config.update('jax_enable_x64', True) before using it)"
        )
