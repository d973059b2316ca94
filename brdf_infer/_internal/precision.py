"""float64 for the model, switched on when asked for: never by importing the package or by
calling it.

The model is stiff (a2 ~ 1e-11; coefficients span 1e-13 to 1e-2) and its likelihood lives in
log space, which float32 cannot carry. JAX's default float is float32 and ``jax_enable_x64``
is process-wide, so importing ``brdf_infer`` leaves it alone. Instead:

- :func:`use_float64` (``brdf_infer.use_float64()``) switches float64 on, with JAX's
  persistent compilation cache (:mod:`brdf_infer._internal.cache`); the command line calls it first.
- The library's entry points (``load_scene``, ``run_posterior``, ``fit_lsq``, ``paper_fit``,
  ``workflow.run``, ``compare_families``, ``predict_rows``, ``design``, ``run_batch``,
  ``simulate_measurements``, ``write_report``) call :func:`ensure_float64`, which refuses
  float32 in one line (:class:`Float32Error`) naming :func:`use_float64`: a library call
  never switches a process-wide setting itself.
- The pure model functions (``brdf_infer.model``) are not guarded: they run under ``jit`` and
  in whatever precision their caller chose; call ``brdf_infer.use_float64()`` first.
"""

from __future__ import annotations

import threading

import jax
import jax.numpy as jnp

_SWITCH = threading.Lock()
_configured = False  # use_float64 ran in this process


class Float32Error(RuntimeError):
    """JAX runs in float32, which cannot carry this model."""


def use_float64(cache: bool = True) -> None:
    """Switch JAX to float64 (``jax_enable_x64``) and, the first time and with ``cache``, on
    to the persistent compilation cache (``$BRDF_INFER_CACHE``, ``~/.cache/brdf_infer``;
    ``BRDF_INFER_CACHE=off`` leaves it off, and so does a cache folder configured before).

    Call it before creating any JAX array: an array made before stays float32. Calling it
    again does nothing more. Both settings are process-wide.

    Args:
        cache: also switch the compilation cache on (the command line's ``--no-cache`` not).
    """
    global _configured
    from brdf_infer._internal.cache import enable_compilation_cache

    with _SWITCH:
        jax.config.update("jax_enable_x64", True)
        if not _configured and cache and jax.config.jax_compilation_cache_dir is None:
            enable_compilation_cache()
        _configured = True


def ensure_float64() -> None:
    """What the library's entry points call first: nothing when float64 is on; else refuse,
    naming :func:`use_float64` (switching a process-wide setting behind the caller's back
    would change every other JAX library in the same process, a notebook's included).

    Raises:
        Float32Error: JAX runs in float32.
    """
    if jax.config.jax_enable_x64:
        return
    raise Float32Error(
        "JAX runs in float32; brdf_infer needs float64: call brdf_infer.use_float64() "
        "(float64 and the compilation cache, for this process) before creating any JAX array"
    )


def require_float64() -> None:
    """Refuse to run when JAX's default float is float32 (the command line checks it after
    :func:`use_float64`, against a setting changed in between).

    Raises:
        Float32Error: ``jax_enable_x64`` is off.
    """
    if jnp.asarray(1.0).dtype != jnp.float64:
        raise Float32Error(
            "JAX runs in float32; brdf_infer needs float64 (call brdf_infer.use_float64() "
            "before using it)"
        )
