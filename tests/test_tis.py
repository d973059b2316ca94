"""Eq. (9): total integrated scatter, its exact 1-D reduction, Table 3 and Sec. 7."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads
from scipy.integrate import quad

from brdf_infer._internal.resources import data_path
from brdf_infer.model import tis, tis_with_error
from brdf_infer.model.params import UV_PAPER, VIS_PAPER, Params
from tests.helpers import assert_allclose, params_from_unit_scale, reference_brdf_hemisphere
from tests.test_paper_fit import PRINTED_UV_HALF_UNIT


def tis_two_dimensional(theta_i: float, params, fold: bool = False) -> float:
    """Eq. (9) as written: adaptive 2-D quadrature of the independent reference BRDF."""
    width = -0.95 * theta_i + 90.5

    def over_phi(theta_deg: float) -> float:
        value, _ = quad(
            lambda phi: reference_brdf_hemisphere(theta_i, theta_deg, phi, params, fold),
            0.0,
            360.0,
            points=[180.0 - width, 180.0, 180.0 + width],
            epsabs=0,
            epsrel=1e-13,
        )
        theta = math.radians(theta_deg)
        return value * math.pi / 180 * math.cos(theta) * math.sin(theta)

    kinks = [abs(params.theta_s0), 87.0]
    value, _ = quad(over_phi, 0.0, 90.0, points=kinks, epsabs=0, epsrel=1e-13, limit=200)
    return value * math.pi / 180


@pytest.mark.parametrize("fold", [False, True])
@pytest.mark.parametrize("theta_i", [5.0, 70.0])
def test_exact_reduction_matches_eq9_in_two_dimensions_to_1e_10(theta_i, fold):
    assert_allclose(
        tis(theta_i, VIS_PAPER, fold), tis_two_dimensional(theta_i, VIS_PAPER, fold), rtol=1e-10
    )


@pytest.mark.parametrize("fold", [False, True])
def test_uv_matches_eq9_in_two_dimensions_at_grazing_incidence(fold):
    assert_allclose(
        tis(80.0, UV_PAPER, fold), tis_two_dimensional(80.0, UV_PAPER, fold), rtol=1e-10
    )


def test_table_three_model_row_reproduced_with_eq10_folding():
    table = np.genfromtxt(data_path("table3_tis.csv"), delimiter=",", names=True)
    values = np.asarray(tis(table["theta_i_deg"], VIS_PAPER, fold=True))
    # The paper truncates: 0.81, 1.09, 1.68, 4.0 %; converged 0.816, 1.093, 1.686, 3.992 %.
    assert_allclose(100 * values, [0.816, 1.093, 1.686, 3.992], atol=5e-4)
    assert np.all(np.abs(values - table["model_tis"]) <= [1e-4, 1e-4, 1e-4, 1e-3])
    # the default, the physical BRDF, is not Table 3: at 70° it scatters 4.262 %, 6.8 % more
    unfolded = np.asarray(tis(table["theta_i_deg"], VIS_PAPER))
    assert_allclose(100 * unfolded[-1], 4.262, atol=5e-4)


def test_uv_tis_unfolded_by_default_exceeds_the_folded_near_grazing():
    """The conservative default: uv-paper's TIS at 85° is 7.899 % without Eq. (10) and 7.465 %
    with it (hand-checked by the 2-D quadrature of the plain-Python model above: 7.8987 and
    7.4650 %), at 70° 5.772 and 5.693 %; near normal incidence the fold changes < 0.1 %."""
    theta_i = np.array([0.0, 70.0, 85.0])
    default = np.asarray(tis(theta_i, UV_PAPER))
    assert_allclose(default, tis(theta_i, UV_PAPER, fold=False), rtol=0)
    folded = np.asarray(tis(theta_i, UV_PAPER, fold=True))
    assert_allclose(100 * default[1:], [5.772, 7.899], atol=5e-4)
    assert_allclose(100 * folded[1:], [5.693, 7.465], atol=5e-4)
    assert default[2] / folded[2] - 1 > 0.05 and default[1] / folded[1] - 1 > 0.01
    assert abs(default[0] / folded[0] - 1) < 1e-3


def test_uv_tis_at_normal_incidence_and_70_deg_as_in_section_7():
    """Sec. 7: "a rough estimation of TIS = π BRDF0 gives ... ∼3.6 % for ∼121.6 nm" and "For
    θi = 70 deg, we obtained a TIS estimation of ∼5.8 % for ∼121.6 nm". The article does not
    say whether that 5.8 % includes the folding of Eq. (10): "Our model [Eqs. (7), (8), and
    (10)]" heads a row of Table 3, the 532-nm comparison with the TIS measured in its Ref. 6
    (0.81, 1.09, 1.68, 4.0 %), and Sec. 7 names no equation for the 121.6-nm figure.

    What the figure allows: half a unit of "5.8" (0.05 %) plus the printing of the four
    coefficients (Sec. 5.3, half a unit of their last digit) carried through TIS(70°),
    Σ |∂TIS/∂cⱼ|·hⱼ = 0.082 % folded, 0.087 % unfolded: 0.132 % and 0.137 % (the old ±0.15 %
    had no derivation). The printed coefficients give 5.693 % folded and 5.772 % unfolded, so
    both readings are checked: the fold moves TIS(70°) by 0.079 %, less than the allowance,
    and the article's figure cannot tell which it is (the reproduced fit of
    tests/test_paper_fit.py gives 5.81 % folded and 5.90 % unfolded, so rounding would pick
    the other reading there). The fold itself is pinned to 5e-4 % in
    test_uv_tis_unfolded_by_default_exceeds_the_folded_near_grazing. Planted by hand, each
    fails here: the folding at θsf = 80° (5.33 %) or with a = 0.035 deg⁻¹ (5.31 %), α = 4.4
    (5.24 %), θs0 = −10° (5.42 %), BRDF0 2.5 % low (5.55 % folded, 5.63 % unfolded)."""
    assert abs(math.pi * UV_PAPER.brdf0 - 0.036) < 0.0005
    assert abs(float(tis(0.0, UV_PAPER, fold=True)) - 0.036) < 0.0005
    values = {}
    for fold in (True, False):
        gradient = jax.grad(lambda p, fold=fold: tis(70.0, p, fold))(UV_PAPER)
        printing = sum(
            abs(float(g)) * h for g, h in zip(gradient[:4], PRINTED_UV_HALF_UNIT[:4], strict=True)
        )
        assert 0.0008 < printing < 0.0009, (fold, printing)
        values[fold] = float(tis(70.0, UV_PAPER, fold))
        assert abs(values[fold] - 0.058) <= 0.0005 + printing, (fold, values[fold])
    # the fold's 0.079 % is inside the allowance of either reading: Sec. 7 cannot tell them
    assert 0.0007 < values[False] - values[True] < 0.0005 + 0.0008


@pytest.mark.full
@pytest.mark.parametrize("fold", [False, True])
def test_converged_at_default_nodes_with_small_error_estimate(fold):
    theta_i = jnp.array([0.0, 30.0, 70.0, 89.0])
    reference = tis(theta_i, UV_PAPER, fold, nodes=256)
    value, error = tis_with_error(theta_i, UV_PAPER, fold)
    assert_allclose(value, reference, rtol=1e-12)
    assert np.all(error < 1e-10 * value)


@pytest.mark.full
def test_batched_over_parameter_sets_and_angles():
    draws = Params(*(np.array([u, v, u]) for u, v in zip(UV_PAPER, VIS_PAPER, strict=True)))
    theta_i = np.array([[5.0, 30.0], [50.0, 70.0]])
    values = tis(theta_i, draws)
    assert values.shape == (3, 2, 2)
    assert_allclose(values[1], tis(theta_i, VIS_PAPER), rtol=1e-14)
    assert_allclose(values[2], values[0], rtol=0)


def test_kink_inside_the_forward_branch_for_positive_theta_s0():
    params = UV_PAPER._replace(theta_s0=20.0, a1=1e-3)
    assert_allclose(tis(40.0, params), tis_two_dimensional(40.0, params), rtol=1e-9)


@pytest.mark.parametrize("fold", [False, True])
def test_gradient_matches_finite_differences_and_is_finite_at_edges(fold):
    def scaled(theta_i, unit):
        return tis(theta_i, params_from_unit_scale(unit, UV_PAPER), fold)

    for theta_i in (0.0, 45.0, 80.0):
        check_grads(scaled, (theta_i, jnp.ones(6)), order=1, modes=["rev"], eps=1e-5)
    for theta_s0 in (0.0, -90.0, 90.0):
        params = UV_PAPER._replace(theta_s0=theta_s0, alpha=0.7)
        grads = jax.grad(lambda p: tis(89.999, p, fold))(params)
        assert all(np.isfinite(g) for g in grads)
