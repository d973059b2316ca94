"""Eq. (8): the full-hemisphere BRDF and its azimuthal weight."""

import jax
import numpy as np
import pytest
from scipy.integrate import quad

from brdf_infer.model import (
    azimuthal_weight,
    azimuthal_weight_integral,
    brdf_hemisphere,
    brdf_inplane,
    log_brdf_hemisphere,
)
from brdf_infer.model.params import PAPER_CONSTANTS, UV_PAPER, VIS_PAPER
from tests.helpers import assert_allclose, reference_brdf_hemisphere


def test_weight_is_a_tent_centred_on_the_forward_plane():
    # theta_i = 30: half-width 90.5 - 28.5 = 62 deg
    phi = np.array([180.0, 149.0, 211.0, 118.0, 90.0, 0.0, 359.0, -180.0, 540.0])
    expected = [1.0, 0.5, 0.5, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0]
    assert_allclose(azimuthal_weight(30.0, phi), expected, rtol=1e-14, atol=1e-15)


@pytest.mark.parametrize("theta_i", [0.0, 30.0, 70.0, 89.0])
def test_weight_integral_closed_form_matches_quadrature(theta_i):
    width = -0.95 * theta_i + 90.5
    numeric, _ = quad(
        lambda phi: float(azimuthal_weight(theta_i, phi)),
        0.0,
        360.0,
        points=[180.0 - width, 180.0, 180.0 + width],
        epsabs=1e-12,
    )
    assert_allclose(azimuthal_weight_integral(theta_i), numeric, rtol=1e-10)
    assert_allclose(azimuthal_weight_integral(theta_i), -0.95 * theta_i + 90.5, rtol=1e-14)


def test_weight_integral_for_half_widths_beyond_180_and_below_zero():
    wide = PAPER_CONSTANTS._replace(c1=0.0, c2_deg=240.0)
    numeric, _ = quad(
        lambda phi: float(azimuthal_weight(0.0, phi, wide)), 0.0, 360.0, points=[180.0]
    )
    assert_allclose(azimuthal_weight_integral(0.0, wide), numeric, rtol=1e-10)
    closed = PAPER_CONSTANTS._replace(c1=0.0, c2_deg=-5.0)
    assert azimuthal_weight_integral(0.0, closed) == 0.0
    assert azimuthal_weight(0.0, 180.0, closed) == 0.0


@pytest.mark.parametrize("fold", [False, True])
def test_specular_plane_reduces_to_the_two_branches(fold):
    theta = np.array([0.0, 20.0, 60.0, 85.0, 90.0])
    forward = brdf_hemisphere(70.0, theta, 180.0, UV_PAPER, fold)
    assert_allclose(forward, brdf_inplane(70.0, theta, UV_PAPER, fold=fold), rtol=1e-13)
    backward = brdf_hemisphere(70.0, theta, 0.0, UV_PAPER, fold)
    assert_allclose(backward, brdf_inplane(70.0, -theta, UV_PAPER), rtol=1e-13)


@pytest.mark.parametrize("fold", [False, True])
@pytest.mark.parametrize("params", [UV_PAPER, VIS_PAPER], ids=["uv", "vis"])
def test_matches_independent_implementation(params, fold):
    rng = np.random.default_rng(0)
    theta_i, theta, phi = rng.uniform(0, 89, 200), rng.uniform(0, 90, 200), rng.uniform(0, 360, 200)
    expected = [
        reference_brdf_hemisphere(*args, params, fold)
        for args in zip(theta_i, theta, phi, strict=True)
    ]
    assert_allclose(brdf_hemisphere(theta_i, theta, phi, params, fold), expected, rtol=1e-12)


def test_without_fold_forward_plane_is_eq7_and_that_is_the_default():
    expected = brdf_inplane(80.0, 88.0, UV_PAPER)
    assert_allclose(brdf_hemisphere(80.0, 88.0, 180.0, UV_PAPER, fold=False), expected, rtol=1e-13)
    assert_allclose(brdf_hemisphere(80.0, 88.0, 180.0, UV_PAPER), expected, rtol=0)
    assert brdf_hemisphere(80.0, 88.0, 180.0, UV_PAPER, fold=True) < 0.5 * expected


@pytest.mark.parametrize(("theta", "phi"), [(0.0, 0.0), (90.0, 180.0), (12.0, 0.0), (45.0, 118.0)])
def test_gradients_finite_at_edges(theta, phi):
    grads = jax.grad(log_brdf_hemisphere, argnums=(0, 1, 2, 3))(30.0, theta, phi, UV_PAPER)
    assert all(np.isfinite(leaf) for leaf in jax.tree_util.tree_leaves(grads))
