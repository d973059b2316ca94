"""Which device a command computes on (``--device``).

One posterior of a small scene is latency-bound: a NUTS step on 42 rows is a few µs of
arithmetic, so a GPU's kernel launches make it slower than a CPU core (27 s on 2 CPU cores
against 62 s on an H100, measured). Many data sets at once — ``batch``, SBC replicates —
and the ray tracer's millions of rays fill an accelerator. ``auto`` therefore keeps the
single-scene commands on the CPU and gives the others the default device (the accelerator
where JAX has one).
"""

from __future__ import annotations

import contextlib

import jax

DEVICES = ("auto", "cpu", "accelerator")
ACCELERATED_COMMANDS = frozenset({"batch", "sbc", "raytrace", "bench"})


def placement(command: str, requested: str = "auto") -> contextlib.AbstractContextManager:
    """The context a command runs in: JAX's default device, or the CPU.

    Args:
        command: the subcommand (``posterior``, ``batch``, ...).
        requested: ``auto`` (the CPU for single-scene commands), ``cpu`` or ``accelerator``
            (JAX's default device, the CPU where there is no accelerator).
    """
    if requested == "accelerator" or (requested == "auto" and command in ACCELERATED_COMMANDS):
        return contextlib.nullcontext()
    return jax.default_device(jax.local_devices(backend="cpu")[0])  # this process's own
