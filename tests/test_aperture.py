"""Eq. (6): solid angle of the detector aperture and the R ↔ BRDF conversion."""

import math

import jax
import numpy as np

from brdf_infer.model import (
    brdf_to_reflectance,
    log_aperture_factor,
    reflectance_to_brdf,
    solid_angle,
)
from tests.helpers import assert_allclose


def test_solid_angle_matches_spherical_cap_formula_for_both_series():
    for d, r in [(7.2, 103.8), (7.5, 110.0)]:
        rho = d / (2 * r)
        assert_allclose(solid_angle(d, r), 2 * math.pi * (1 - math.cos(rho)), rtol=1e-13)


def test_solid_angle_hand_value_series_one():
    # rho = 7.2 / 207.6 = 0.0346821; Omega = pi rho^2 (1 - rho^2/12 + rho^4/360 - ...) sr
    rho = 7.2 / 207.6
    assert_allclose(
        solid_angle(7.2, 103.8), math.pi * rho**2 * (1 - rho**2 / 12 + rho**4 / 360), rtol=1e-11
    )


def test_reflectance_to_brdf_of_table_one_mean_at_18_deg():
    omega = 2 * math.pi * (1 - math.cos(7.2 / 207.6))
    expected = 5.72e-5 / (omega * math.cos(math.radians(18)))
    assert_allclose(reflectance_to_brdf(5.72e-5, 18.0, 7.2, 103.8), expected, rtol=1e-13)
    assert 0.0159 < expected < 0.0160


def test_conversion_round_trips_and_log_factor_agrees():
    theta_s = np.array([-75.0, 0.0, 30.0, 89.0])
    brdf = np.array([1e-3, 2e-2, 0.3, 5.0])
    reflectance = brdf_to_reflectance(brdf, theta_s, 7.5, 110.0)
    assert_allclose(reflectance_to_brdf(reflectance, theta_s, 7.5, 110.0), brdf, rtol=1e-14)
    assert_allclose(
        np.log(reflectance), np.log(brdf) + log_aperture_factor(theta_s, 7.5, 110.0), rtol=1e-13
    )


def test_conversion_is_jittable_and_differentiable():
    grad = jax.grad(lambda d: reflectance_to_brdf(1e-4, 45.0, d, 110.0))(7.5)
    assert np.isfinite(grad) and grad < 0
