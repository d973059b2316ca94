"""Model families: each BRDF against an independent plain-NumPy implementation of the ray
tracers' definitions, each TIS against a brute-force hemisphere integral, finite gradients."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads
from scipy import integrate

from brdf_infer.model import FAMILIES, FAMILY_NAMES, family
from brdf_infer.model.params import UV_PAPER
from tests.helpers import assert_allclose, reference_brdf_hemisphere

PHYSICAL = {
    "abg": {"A": 2.0e-3, "B": 5.0e-3, "g": 1.8},
    "harvey-shack": {"b0": 0.4, "L": 0.05, "S": -2.2},
    "lambertian": {"tis": 0.03},
    "lambertian+abg": {"rho_d": 0.01, "A": 2.0e-3, "B": 5.0e-3, "g": 1.8},
}


def reference_brdf(name: str, theta_i: float, theta: float, phi: float, p: dict) -> float:
    """The families from their textbook definitions: β = sin θ (cos φ', sin φ') with φ' the
    azimuth from the specular plane (forward plane at φ = 180° in the paper's frame), β₀ =
    (sin θi, 0); plain floats."""
    azimuth = math.radians(phi - 180.0)
    bx = math.sin(math.radians(theta)) * math.cos(azimuth) - math.sin(math.radians(theta_i))
    by = math.sin(math.radians(theta)) * math.sin(azimuth)
    rho = math.hypot(bx, by)
    abg = p.get("A", 0.0) / (p.get("B", 1.0) + rho ** p.get("g", 1.0)) if "A" in p else 0.0
    if name == "abg":
        return abg
    if name == "harvey-shack":
        return p["b0"] * (1.0 + (rho / p["L"]) ** 2) ** (p["S"] / 2.0)
    if name == "lambertian":
        return p["tis"] / math.pi
    return p["rho_d"] / math.pi + abg


def _physical(name: str) -> dict:
    return {k: jnp.asarray(v) for k, v in PHYSICAL[name].items()}


@pytest.mark.parametrize("name", list(FAMILIES))
def test_family_brdf_matches_its_textbook_definition_over_the_hemisphere(name):
    rng = np.random.default_rng(3)
    points = np.column_stack(
        [rng.uniform(0, 89, 40), rng.uniform(0, 90, 40), rng.uniform(0, 360, 40)]
    )
    points = np.vstack([points, [[30.0, 30.0, 180.0], [60.0, 90.0, 180.0], [0.0, 0.0, 0.0]]])
    member = family(name)
    values = np.exp(member.log_brdf(points[:, 0], points[:, 1], points[:, 2], _physical(name)))
    expected = [reference_brdf(name, *point, PHYSICAL[name]) for point in points]
    assert_allclose(values, expected, rtol=1e-12)


@pytest.mark.parametrize("fold", [None, False, True])
def test_strumik2024_family_is_eqs_7_8_and_10_only_when_folded(fold):
    member = family("strumik2024") if fold is None else family("strumik2024", fold)
    physical = {k: jnp.asarray(v) for k, v in UV_PAPER._asdict().items()}
    points = ((20.0, 40.0, 180.0), (60.0, 30.0, 0.0), (45.0, 50.0, 120.0), (80.0, 88.0, 180.0))
    for theta_i, theta, phi in points:
        value = float(jnp.exp(member.log_brdf(theta_i, theta, phi, physical)))
        expected = reference_brdf_hemisphere(theta_i, theta, phi, UV_PAPER, bool(fold))
        assert value == pytest.approx(expected, rel=1e-10)


def _brute_force_tis(name: str, theta_i: float) -> float:
    """∫ BRDF cos θ dΩ over the hemisphere by adaptive quadrature (mirror symmetric in φ)."""

    def integrand(theta_deg, phi_deg):
        brdf = reference_brdf(name, theta_i, theta_deg, phi_deg, PHYSICAL[name])
        theta = math.radians(theta_deg)
        return brdf * math.cos(theta) * math.sin(theta) * math.radians(1.0) ** 2

    # split at the specular direction's θ, where the lobes peak
    total = 0.0
    for low, high in ((0.0, theta_i), (theta_i, 90.0)):
        if high > low:
            total += integrate.dblquad(integrand, 0.0, 180.0, low, high, epsrel=1e-10)[0]
    return 2.0 * total


@pytest.mark.parametrize("name", list(FAMILIES))
@pytest.mark.parametrize("theta_i", [0.0, 40.0, 80.0])
def test_family_tis_matches_a_brute_force_hemisphere_integral(name, theta_i):
    member = family(name)
    value = float(member.tis(jnp.asarray(theta_i), _physical(name)))
    assert value == pytest.approx(_brute_force_tis(name, theta_i), rel=1e-8)


@pytest.mark.parametrize("name", list(FAMILIES))
def test_family_gradients_are_finite_at_specular_and_grazing_and_match_differences(name):
    member = family(name)
    internal = {
        c.site: jnp.asarray(v)
        for c, v in zip(
            member.coordinates, (-2.0, -3.0, 1.7, 0.5)[: len(member.coordinates)], strict=True
        )
    }

    def log_brdf(z, theta_i, theta_s):
        return member.log_brdf_signed(theta_i, theta_s, member.to_physical(z))

    for theta_i, theta_s in ((30.0, 30.0), (0.0, 0.0), (80.0, 90.0), (45.0, -90.0)):
        gradient = jax.grad(log_brdf)(internal, theta_i, theta_s)
        assert all(np.isfinite(v) for v in jax.tree_util.tree_leaves(gradient))
        angle_gradient = jax.grad(log_brdf, argnums=(1, 2))(internal, theta_i, theta_s)
        assert np.all(np.isfinite(angle_gradient))
    check_grads(lambda z: log_brdf(z, 40.0, 25.0), (internal,), order=1, modes=["rev"])


def test_family_names_are_listed_with_the_reference_first():
    assert FAMILY_NAMES[0] == "strumik2024"
    assert set(FAMILY_NAMES) == {
        "strumik2024",
        "abg",
        "harvey-shack",
        "lambertian",
        "lambertian+abg",
    }
