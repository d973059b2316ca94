"""Timing helpers: compile time apart from run time, best of several runs."""

from __future__ import annotations

import os
import platform
import time
from collections.abc import Callable
from typing import Any

import jax


def timed(function: Callable[..., Any], *args: Any, repeat: int = 5) -> tuple[Any, float, float]:
    """(result, first-call seconds minus a run, best run seconds) of ``function(*args)``.

    The first call includes tracing and compilation; the difference to the best later call is
    reported as compile time.
    """
    clock = time.perf_counter()
    result = jax.block_until_ready(function(*args))
    first = time.perf_counter() - clock
    best = float("inf")
    for _ in range(repeat):
        clock = time.perf_counter()
        jax.block_until_ready(function(*args))
        best = min(best, time.perf_counter() - clock)
    return result, max(first - best, 0.0), best


def machine_description() -> str:
    """CPU, core count and JAX backend, for the report header."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as handle:
            for line in handle:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return (
        f"{cpu}, {os.cpu_count()} cores, JAX {jax.__version__} on {jax.default_backend()}, "
        f"Python {platform.python_version()}"
    )
