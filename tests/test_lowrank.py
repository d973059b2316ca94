"""The fused small linear algebra of the posterior (brdf_infer._internal.lowrank).

Checked against NumPy/SciPy, the posterior's potential against the earlier implementation
(LAPACK Cholesky and NumPyro's LowRankMultivariateNormal, kept here as the reference), the
gradients against finite differences, and the compiled programs for LAPACK custom calls
(which deadlocked concurrent executions on a 2-core CPU).
"""

from __future__ import annotations

import re

import jax
import jax.numpy as jnp
import numpy as np
import numpyro.distributions as dist
import pytest
from jax.test_util import check_grads
from scipy import stats

from brdf_infer._internal.lowrank import (
    BlockCholesky,
    cholesky,
    leave_one_out_conditionals,
    log_density_over_scales,
    low_rank_normal_log_density,
    solve_lower,
    solve_upper_transposed,
)
from brdf_infer.posterior import _likelihood as likelihood
from brdf_infer.posterior import _model as posterior_model
from brdf_infer.posterior._model import build_posterior_model
from brdf_infer.posterior._potential import FlatPotential
from brdf_infer.scene import load_scene


def _spd(rng, size: int) -> np.ndarray:
    a = rng.normal(size=(size, size))
    return a @ a.T + size * np.eye(size)


def _grouped_factor(rng, rows: int, groups: int, extra: int) -> np.ndarray:
    """W whose first ``groups`` columns have disjoint rows (as per-sample effects do)."""
    members = np.zeros((rows, groups))
    members[np.arange(rows), rng.integers(0, groups, rows)] = 1.0
    return np.concatenate([0.3 * members, 0.2 * rng.normal(size=(rows, extra))], axis=1)


@pytest.mark.full
@pytest.mark.parametrize("extra", [0, 2])
@pytest.mark.parametrize("groups", [0, 3])
def test_density_and_loo_with_only_disjoint_or_no_shared_columns(groups, extra):
    """W may have no columns beyond the per-sample ones (a scene without calibration, with no
    rotation setting of two rows), or none at all: the Schur complement is then 0 × 0."""
    rng = np.random.default_rng(4)
    rows = 6
    if groups:
        factor = _grouped_factor(rng, rows, groups, extra)
    else:
        factor = 0.2 * rng.normal(size=(rows, extra))
    diagonal = rng.uniform(0.05, 0.2, rows)
    mean, value = rng.normal(size=rows), rng.normal(size=rows)
    covariance = np.diag(diagonal) + factor @ factor.T
    got = low_rank_normal_log_density(
        jnp.asarray(value),
        jnp.asarray(mean),
        jnp.asarray(factor),
        jnp.asarray(diagonal),
        disjoint=groups,
    )
    expected = stats.multivariate_normal(mean, covariance).logpdf(value)
    assert float(got) == pytest.approx(expected, rel=1e-12)
    sd = leave_one_out_conditionals(
        jnp.asarray(value), jnp.asarray(mean), jnp.asarray(factor), jnp.asarray(diagonal), groups
    )[1]
    precision = np.linalg.inv(covariance)
    np.testing.assert_allclose(np.asarray(sd), 1 / np.sqrt(np.diag(precision)), rtol=1e-11)


@pytest.mark.full
def test_cholesky_and_triangular_solves_match_numpy():
    rng = np.random.default_rng(1)
    matrix = _spd(rng, 7)
    lower = np.asarray(cholesky(jnp.asarray(matrix)))
    np.testing.assert_allclose(lower, np.linalg.cholesky(matrix), rtol=1e-12, atol=1e-12)
    rhs = rng.normal(size=(7, 3))
    np.testing.assert_allclose(
        solve_lower(jnp.asarray(lower), jnp.asarray(rhs)), np.linalg.solve(lower, rhs), rtol=1e-11
    )
    np.testing.assert_allclose(
        solve_upper_transposed(jnp.asarray(lower), jnp.asarray(rhs[:, 0])),
        np.linalg.solve(lower.T, rhs[:, 0]),
        rtol=1e-11,
    )


def test_block_cholesky_with_a_diagonal_leading_block_matches_numpy():
    rng = np.random.default_rng(2)
    factor = _grouped_factor(rng, 30, 5, 4)
    matrix = np.eye(9) + factor.T @ factor  # leading 5 x 5 block diagonal
    block = BlockCholesky(jnp.asarray(matrix), 5)
    lower = np.linalg.cholesky(matrix)
    rhs = rng.normal(size=9)
    np.testing.assert_allclose(block.solve_lower(jnp.asarray(rhs)), np.linalg.solve(lower, rhs))
    np.testing.assert_allclose(
        float(block.log_diagonal_sum()), np.sum(np.log(np.diag(lower))), rtol=1e-12
    )


@pytest.mark.full
@pytest.mark.parametrize("disjoint", [0, 6])
def test_low_rank_normal_matches_scipy_and_its_gradient_finite_differences(disjoint):
    rng = np.random.default_rng(3)
    factor = _grouped_factor(rng, 40, 6, 3)
    diagonal = rng.uniform(0.01, 0.05, 40)
    mean = rng.normal(size=40)
    value = mean + rng.normal(size=40) * 0.2
    expected = stats.multivariate_normal(mean, np.diag(diagonal) + factor @ factor.T).logpdf(value)
    # compiled: eager, the unrolled factorisation dispatches (and compiles) op by op
    log_density = jax.jit(low_rank_normal_log_density, static_argnames="disjoint")
    got = log_density(
        jnp.asarray(value),
        jnp.asarray(mean),
        jnp.asarray(factor),
        jnp.asarray(diagonal),
        disjoint=disjoint,
    )
    np.testing.assert_allclose(float(got), expected, rtol=1e-11)
    check_grads(
        lambda f, d: log_density(jnp.asarray(value), jnp.asarray(mean), f, d, disjoint=disjoint),
        (jnp.asarray(factor), jnp.asarray(diagonal)),
        order=1,
        modes=["rev"],
        eps=1e-6,  # D is 0.01-0.05: a larger step's second-order error shows at 1e-4
        rtol=1e-6,
    )


def test_leave_one_out_conditionals_with_a_diagonal_block_match_the_plain_ones():
    rng = np.random.default_rng(4)
    factor = jnp.asarray(_grouped_factor(rng, 25, 4, 2))
    diagonal = jnp.asarray(rng.uniform(0.01, 0.05, 25))
    value, mean = jnp.asarray(rng.normal(size=25)), jnp.zeros(25)
    conditionals = jax.jit(leave_one_out_conditionals, static_argnames="disjoint")
    plain = conditionals(value, mean, factor, diagonal)
    blocked = conditionals(value, mean, factor, diagonal, disjoint=4)
    for a, b in zip(plain, blocked, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-12)


def _lapack_whitened_coefficients(
    design, target, factor, diagonal, prior_mean, prior_sd, standard, disjoint=0
):
    """The earlier implementation (LAPACK Cholesky, cho_solve), kept as the reference."""
    del disjoint
    design_d = design / diagonal[:, None]
    factor_d = factor / diagonal[:, None]
    capacitance = jnp.eye(factor.shape[1]) + factor.T @ factor_d
    capacitance_cholesky = jnp.linalg.cholesky(capacitance)

    def woodbury(left, right):
        inner = jax.scipy.linalg.cho_solve((capacitance_cholesky, True), factor.T @ right)
        return left.T @ (right * diagonal[:, None]) - (factor.T @ left).T @ inner

    precision = jnp.diag(1.0 / prior_sd**2) + woodbury(design_d, design_d)
    lower = jnp.linalg.cholesky(precision)
    rhs = prior_mean / prior_sd**2 + woodbury(design_d, (target / diagonal)[:, None])[:, 0]
    mean = jax.scipy.linalg.cho_solve((lower, True), rhs)
    offset = jax.scipy.linalg.solve_triangular(lower.T, standard, lower=False)
    return mean + offset, -jnp.sum(jnp.log(jnp.diag(lower)))


class _LapackLowRankNormal(dist.LowRankMultivariateNormal):
    def __init__(self, mean, factor, diagonal, keep=None, disjoint=0):
        del keep, disjoint
        super().__init__(mean, factor, diagonal)


@pytest.fixture(scope="module")
def lya_potentials():
    scene = load_scene("lya")
    measurements = scene.load_measurements()
    model = build_posterior_model(scene, measurements)
    return model, FlatPotential(model)


@pytest.mark.full
def test_potential_equals_the_earlier_lapack_implementation(lya_potentials, monkeypatch):
    model, flat = lya_potentials
    rng = np.random.default_rng(5)
    points = jnp.asarray(rng.uniform(-1.5, 1.5, (20, flat.dimension)))
    ours = jax.jit(jax.vmap(lambda z: flat.potential(z, model.data)))(points)
    monkeypatch.setattr(posterior_model, "whitened_coefficients", _lapack_whitened_coefficients)
    monkeypatch.setattr(likelihood, "LowRankNormal", _LapackLowRankNormal)
    reference = jax.jit(jax.vmap(lambda z: FlatPotential(model).potential(z, model.data)))(points)
    assert np.all(np.isfinite(ours))
    np.testing.assert_allclose(ours, reference, rtol=1e-10)


@pytest.mark.full
def test_compiled_posterior_programs_call_no_lapack(lya_potentials):
    model, flat = lya_potentials
    z = jnp.zeros(flat.dimension)
    programs = {
        "value and gradient": jax.jit(jax.value_and_grad(flat.potential)).lower(z, model.data),
        "constrain, vmapped": jax.jit(jax.vmap(flat.constrain, (0, None))).lower(
            jnp.zeros((3, flat.dimension)), model.data
        ),
    }
    for name, lowered in programs.items():
        calls = set(re.findall(r'custom_call_target="([^"]+)"', lowered.compile().as_text()))
        assert not {c for c in calls if "lapack" in c}, (name, calls)


@pytest.mark.full
def test_masked_rows_leave_the_likelihood_exactly():
    rng = np.random.default_rng(6)
    factor = _grouped_factor(rng, 12, 3, 2)
    diagonal = rng.uniform(0.01, 0.05, 12)
    mean, value = rng.normal(size=12), rng.normal(size=12)
    keep = np.arange(12) < 9
    full = low_rank_normal_log_density(
        jnp.asarray(value[:9]),
        jnp.asarray(mean[:9]),
        jnp.asarray(factor[:9]),
        jnp.asarray(diagonal[:9]),
    )
    parts = likelihood.LikelihoodParts(
        jnp.asarray(mean), jnp.asarray(factor), jnp.asarray(diagonal)
    )
    masked_factor, masked_diagonal = likelihood.mask_rows(
        jnp.asarray(keep), parts.factor, parts.diagonal
    )
    padded = likelihood.LowRankNormal(
        jnp.where(keep, parts.mean, jnp.asarray(value)),
        masked_factor,
        masked_diagonal,
        jnp.asarray(keep),
    ).log_prob(jnp.asarray(value))
    np.testing.assert_allclose(float(padded), float(full), rtol=1e-12)


@pytest.mark.full
def test_the_density_over_sample_scales_is_scipys_at_every_scale():
    """:func:`log_density_over_scales` (the rows read once, a (q, q) factorisation per τ)
    against scipy's dense normal with W's first columns multiplied by each τ."""
    rng = np.random.default_rng(7)
    rows, groups = 9, 3
    factor = _grouped_factor(rng, rows, groups, 2)
    diagonal = rng.uniform(0.05, 0.2, rows)
    mean, value = rng.normal(size=rows), rng.normal(size=rows)
    scales = np.array([1e-6, 0.1, 1.0, 3.0])
    got = log_density_over_scales(
        *(jnp.asarray(a) for a in (value, mean, factor, diagonal)), groups, jnp.asarray(scales)
    )
    for scale, ours in zip(scales, np.asarray(got), strict=True):
        scaled = factor * np.where(np.arange(factor.shape[1]) < groups, scale, 1.0)
        covariance = np.diag(diagonal) + scaled @ scaled.T
        assert ours == pytest.approx(
            stats.multivariate_normal(mean, covariance).logpdf(value), rel=1e-12
        )
