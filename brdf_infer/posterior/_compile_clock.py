"""Measure how much of a block's wall time JAX spent tracing, lowering and compiling."""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator

from jax import monitoring

_COMPILE_EVENTS = (
    "/jax/core/compile/jaxpr_trace_duration",
    "/jax/core/compile/jaxpr_to_mlir_module_duration",
    "/jax/core/compile/backend_compile_duration",
)
_lock = threading.Lock()
_open_clocks: list[list[float]] = []


def _listener(event: str, duration: float, **_: object) -> None:
    if event in _COMPILE_EVENTS:
        with _lock:
            for clock in _open_clocks:
                clock[0] += duration


monitoring.register_event_duration_secs_listener(_listener)


@contextlib.contextmanager
def compile_clock() -> Iterator[list[float]]:
    """Yields a one-element list that accumulates JAX compile seconds inside the block."""
    clock = [0.0]
    with _lock:
        _open_clocks.append(clock)
    try:
        yield clock
    finally:
        with _lock:
            _open_clocks.remove(clock)
