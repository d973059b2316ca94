"""Shared test utilities: dtype-aware comparisons, an independent reference model, the CLI."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from brdf_infer.cli import main

REPO = Path(__file__).resolve().parents[1]


def assert_allclose(actual, desired, *, rtol: float | None = None, atol: float = 0.0) -> None:
    """``np.testing.assert_allclose`` with a float64 default of rtol = 1e-12."""
    actual = np.asarray(actual)
    assert actual.dtype in (np.float64, np.complex128, np.bool_, np.int64), actual.dtype
    np.testing.assert_allclose(actual, desired, rtol=1e-12 if rtol is None else rtol, atol=atol)


def reference_brdf_inplane(theta_i: float, theta_s: float, p, fold: bool = False) -> float:
    """Eq. (7) (and Eq. 10) in plain Python floats, written from the paper independently."""
    if theta_s >= p.theta_s0:
        x = theta_s - p.theta_s0
        value = p.brdf0 * math.exp(
            p.a1 * theta_i * x + p.a2 * theta_i * x**p.alpha + p.a3 * theta_i**2 * x**p.alpha
        )
    else:
        value = p.brdf0
    if fold and theta_s >= 0:
        value *= (1.0 - math.erf(0.35 * (theta_s - 87.0))) / 2.0
    return value


def reference_brdf_hemisphere(
    theta_i: float, theta: float, phi: float, p, fold: bool = False
) -> float:
    """Eq. (8) (with Eq. 10 when ``fold``), plain Python, paper constants (c1 = −0.95,
    c2 = 90.5°)."""
    width = -0.95 * theta_i + 90.5
    distance = abs(phi - 180.0)
    weight = 1.0 - distance / width if distance < width else 0.0
    forward = reference_brdf_inplane(theta_i, theta, p, fold=fold)
    backward = reference_brdf_inplane(theta_i, -theta, p)
    return weight * forward + (1.0 - weight) * backward


def params_from_unit_scale(unit_vector, reference):
    """Params = reference × unit_vector: a well-scaled coordinate for finite differences.

    In paper units a2 ~ 1e-11 and a3 ~ 1e-12, so a finite-difference step must be relative.
    """
    return type(reference)(*(unit_vector * jnp.asarray(reference)))


def run_cli(*argv: str, capsys) -> tuple[int, str, str]:
    """Run ``brdf-infer ARGV`` in-process; returns (exit code, stdout, stderr)."""
    try:
        code = main(list(argv))
    except SystemExit as exit_:  # argparse usage errors
        code = exit_.code
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def run_cli_process(*argv: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run ``python -m brdf_infer ARGV`` as a separate process."""
    return subprocess.run(
        [sys.executable, "-m", "brdf_infer", *argv],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=600,
    )


def run_on_forced_cpu_devices(
    script: str, argument: Path, devices: int, timeout: int = 900
) -> None:
    """Run ``python -c script argument`` in a fresh process whose JAX sees ``devices`` CPU
    devices (``--xla_force_host_platform_device_count``); fails the test on a non-zero exit."""
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    env["XLA_FLAGS"] = f"--xla_force_host_platform_device_count={devices}"
    done = subprocess.run(
        [sys.executable, "-c", script, str(argument)],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
    )
    assert done.returncode == 0, done.stderr[-2000:]
