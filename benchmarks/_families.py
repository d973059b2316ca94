"""Benchmark of the model families: each lobe family's TIS quadrature against an adaptive
reference integral (error next to run time), and the PSIS-LOO comparison on the bundled data."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from scipy import integrate

from brdf_infer.model import (
    CHECK_QUADRATURE,
    FIT_QUADRATURE,
    PRECISE_QUADRATURE,
    abg_integral,
    family,
    harvey_shack_integral,
)
from brdf_infer.studies.compare import CompareSettings, compare_families

ABG = {"A": 2.0e-3, "B": 5.0e-3, "g": 1.8}
HARVEY_SHACK = {"b0": 0.4, "L": 0.05, "S": -2.2}
QUADRATURES = (
    ("fit", FIT_QUADRATURE),
    ("precise", PRECISE_QUADRATURE),
    ("check", CHECK_QUADRATURE),
)
THETA_I_DEG = (0.0, 40.0, 80.0)


@dataclass(frozen=True)
class QuadratureRow:
    family: str
    quadrature: str
    max_error: float
    microseconds: float

    @property
    def cells(self) -> list[str]:
        return [self.family, self.quadrature, f"{self.max_error:.1e}", f"{self.microseconds:.0f}"]


def _reference(name: str, theta_i: float) -> float:
    """∫ BSDF cos θ dΩ / (BSDF scale) by adaptive quadrature in (θ, φ), split at θi."""
    member = family(name)
    physical = {k: jnp.asarray(v) for k, v in (ABG if name == "abg" else HARVEY_SHACK).items()}
    scale = ABG["A"] if name == "abg" else HARVEY_SHACK["b0"]

    def integrand(theta_deg, phi_deg):
        value = float(jnp.exp(member.log_brdf(theta_i, theta_deg, phi_deg, physical))) / scale
        theta = math.radians(theta_deg)
        return value * math.cos(theta) * math.sin(theta) * math.radians(1.0) ** 2

    total = 0.0
    for low, high in ((0.0, theta_i), (theta_i, 90.0)):
        if high > low:
            total += integrate.dblquad(integrand, 0.0, 180.0, low, high, epsrel=1e-11)[0]
    return 2.0 * total


def quadrature_rows(quick: bool) -> list[QuadratureRow]:
    """Max relative error over θi = 0, 40, 80° and time per integral (after compiling)."""
    angles = THETA_I_DEG[:2] if quick else THETA_I_DEG
    rows = []
    for name in ("abg", "harvey-shack"):
        reference = np.array([_reference(name, t) for t in angles])
        for label, quadrature in QUADRATURES:
            if name == "abg":
                log_b, g = math.log(ABG["B"]), ABG["g"]
                one = jax.jit(lambda b, q=quadrature, lb=log_b, gg=g: abg_integral(lb, gg, b, q))
            else:
                log_l, slope = math.log(HARVEY_SHACK["L"]), HARVEY_SHACK["S"]
                one = jax.jit(
                    lambda b, q=quadrature, ll=log_l, s=slope: harvey_shack_integral(ll, s, b, q)
                )
            sines = np.sin(np.radians(angles))
            values = np.array([float(one(b)) for b in sines])
            repeats = 50
            clock = time.perf_counter()
            for _ in range(repeats):
                jax.block_until_ready(one(sines[-1]))
            seconds = (time.perf_counter() - clock) / repeats
            error = float(np.max(np.abs(values / reference - 1.0)))
            rows.append(QuadratureRow(name, label, error, 1e6 * seconds))
    return rows


def comparison_row(scene, measurements, quick: bool) -> dict:
    """The five families on the bundled data (compare's default settings unless quick)."""
    settings = CompareSettings(draws=300, warmup=300) if quick else CompareSettings()
    names = ["strumik2024", "abg", "harvey-shack", "lambertian", "lambertian+abg"]
    return compare_families(scene, measurements, names, settings).as_json()
