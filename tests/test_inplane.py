"""Eq. (7) in the specular plane and the folding term of Eq. (10)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from brdf_infer.model import brdf_inplane, log_brdf_inplane, log_fold, positive_power
from brdf_infer.model.params import UV_PAPER, VIS_PAPER, Params
from tests.helpers import assert_allclose, params_from_unit_scale, reference_brdf_inplane


def test_uv_paper_value_by_hand_at_specular_18_deg():
    # x = 18 + 12 = 30; 30^4.5 = 810000 * sqrt(30)
    x_alpha = 810000.0 * math.sqrt(30.0)
    exponent = 4.02e-4 * 18 * 30 + (-6.9e-11 * 18 + 1.34e-12 * 18**2) * x_alpha
    assert_allclose(brdf_inplane(18.0, 18.0, UV_PAPER), 1.14e-2 * math.exp(exponent), rtol=1e-13)


@pytest.mark.parametrize("params", [UV_PAPER, VIS_PAPER], ids=["uv", "vis"])
def test_matches_independent_implementation_on_a_grid(params):
    theta_i, theta_s = np.meshgrid(np.linspace(0, 89, 12), np.linspace(-90, 90, 37))
    expected = np.vectorize(lambda i, s: reference_brdf_inplane(i, s, params))(theta_i, theta_s)
    assert_allclose(brdf_inplane(theta_i, theta_s, params), expected, rtol=1e-12)
    folded = np.vectorize(lambda i, s: reference_brdf_inplane(i, s, params, fold=True))(
        theta_i, theta_s
    )
    assert_allclose(brdf_inplane(theta_i, theta_s, params, fold=True), folded, rtol=1e-12)


def test_constant_plateau_below_theta_s0_and_continuous_at_it():
    below = brdf_inplane(80.0, np.array([-90.0, -50.0, -12.000001]), UV_PAPER)
    assert_allclose(below, np.full(3, UV_PAPER.brdf0), rtol=1e-14)
    assert_allclose(brdf_inplane(80.0, -12.0, UV_PAPER), UV_PAPER.brdf0, rtol=1e-14)
    assert_allclose(brdf_inplane(80.0, -12.0 + 1e-9, UV_PAPER), UV_PAPER.brdf0, rtol=1e-9)


def test_broadcasts_over_a_batch_of_parameter_sets():
    batch = Params(*(np.array([a, b]) for a, b in zip(UV_PAPER, VIS_PAPER, strict=True)))
    values = brdf_inplane(60.0, 45.0, batch)
    assert values.shape == (2,)
    assert_allclose(values[1], brdf_inplane(60.0, 45.0, VIS_PAPER))


@pytest.mark.full
def test_fold_is_erfc_over_two_and_finite_far_in_both_tails():
    theta = np.array([0.0, 80.0, 87.0, 90.0])
    expected = [math.erfc(0.35 * (t - 87.0)) / 2 for t in theta]
    assert_allclose(np.exp(log_fold(theta)), expected, rtol=1e-13)
    far = log_fold(np.array([-1e4, 1e4]))
    assert np.all(np.isfinite(far)) and far[1] < -1e6
    assert np.all(np.isfinite(jax.vmap(jax.grad(log_fold))(jnp.array([-1e4, 87.0, 1e4]))))


def test_positive_power_has_finite_gradients_at_zero_and_below_for_small_alpha():
    for alpha in (0.3, 1.0, 4.5):
        for x in (-1.0, 0.0):
            gx, galpha = jax.grad(positive_power, argnums=(0, 1))(x, alpha)
            assert gx == 0.0 and galpha == 0.0
        assert np.isfinite(jax.grad(positive_power)(1e-300, alpha))


EDGE_POINTS = [
    (80.0, -12.0),  # exactly at theta_s0
    (80.0, -12.0 + 1e-12),
    (80.0, -12.0 - 1e-12),
    (80.0, -60.0),  # on the plateau
    (0.0, 0.0),
    (89.999, 90.0),
    (45.0, -90.0),
]


@pytest.mark.parametrize("alpha", [0.5, 1.0, 4.5, 12.0])
@pytest.mark.parametrize(("theta_i", "theta_s"), EDGE_POINTS)
def test_gradient_finite_at_edge_points(theta_i, theta_s, alpha):
    params = UV_PAPER._replace(alpha=alpha)
    for fold in (False, True):
        grads = jax.grad(log_brdf_inplane, argnums=(0, 1, 2))(theta_i, theta_s, params, fold)
        leaves = jax.tree_util.tree_leaves(grads)
        assert all(np.isfinite(leaf) for leaf in leaves), (theta_i, theta_s, alpha, fold, grads)


def test_log_brdf_finite_where_brdf_overflows():
    huge = Params(1.0, 10.0, 1e3, 1e2, 4.5, -12.0)
    assert not np.isfinite(float(brdf_inplane(80.0, 80.0, huge)))
    value = log_brdf_inplane(80.0, 80.0, huge)
    assert np.isfinite(value) and value > 700
    assert all(np.isfinite(g) for g in jax.grad(log_brdf_inplane, argnums=2)(80.0, 80.0, huge))


@pytest.mark.full
def test_gradients_agree_with_finite_differences():
    def scaled(theta_i, theta_s, unit):
        return log_brdf_inplane(theta_i, theta_s, params_from_unit_scale(unit, UV_PAPER), True)

    for theta_i, theta_s in [(18.0, 18.0), (45.0, 60.0), (80.0, 85.0), (75.0, -20.0)]:
        check_grads(
            scaled, (theta_i, theta_s, jnp.ones(6)), order=2, modes=["rev", "fwd"], eps=1e-5
        )
