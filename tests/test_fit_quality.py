"""A fit's own quality statement: its p-value against the closed form, the 'poor' call almost
never made on a right model and always made when the σ are planted a factor 2 too small."""

import math

import numpy as np
import pytest

from brdf_infer.fit_quality import POOR_P_VALUE, FitQuality, scaled_sigma
from brdf_infer.lsq import paule_mandel


def chi2_survival_even_dof(x: float, dof: int) -> float:
    """P(χ²_dof ≥ x) for even dof: exp(−x/2) Σ_{j<dof/2} (x/2)^j / j! (Poisson sum)."""
    half = x / 2
    return math.exp(-half) * sum(half**j / math.factorial(j) for j in range(dof // 2))


@pytest.mark.parametrize(("chi2", "dof"), [(36.0, 36), (72.0, 36), (10.0, 4), (3.0, 10)])
def test_p_value_is_the_chi2_survival_function(chi2, dof):
    assert FitQuality(chi2, dof).p_value == pytest.approx(
        chi2_survival_even_dof(chi2, dof), rel=1e-10
    )


def test_poor_is_rare_on_a_right_model_and_the_rule_with_sigma_half_their_size():
    """χ² of 36 standard normal residuals (the bundled scene's dof): the right σ are called
    poor at the rate P(χ²₃₆ > 72) = 3.4e-4 ≤ 0.001; σ planted a factor 2 too small (χ²/dof ≈
    4) are called poor at the rate P(4 χ²₃₆ > 72) = P(χ²₃₆ > 18) = 0.994, within 4 binomial
    standard errors."""
    rng = np.random.default_rng(7)
    chi2 = np.sum(rng.standard_normal((20_000, 36)) ** 2, axis=1)
    right = np.mean([FitQuality(float(c), 36).poor for c in chi2])
    assert right <= POOR_P_VALUE
    planted = np.mean([FitQuality(float(4 * c), 36).poor for c in chi2])
    power = chi2_survival_even_dof(18.0, 36)
    assert power > 0.99
    assert abs(planted - power) < 4 * math.sqrt(power * (1 - power) / chi2.size)


def test_few_dof_need_more_than_twice_the_chi2():
    """χ²/dof = 2.5 on 5 dof has p = 0.03: chance, not a poor fit; on 100 dof it is."""
    assert not FitQuality(12.5, 5).poor
    assert FitQuality(250.0, 100).poor


def test_statements_say_what_they_measured():
    poor = FitQuality(39 * 144.0, 39)
    assert poor.statement.startswith("poor: χ²/dof = 144 for 39 dof (p < 1e-300)")
    assert "factor 12" in poor.statement and poor.sigma_factor == pytest.approx(12.0)
    assert scaled_sigma({"A": 1e-5}, poor.sigma_factor)["A"] == pytest.approx(1.2e-4)
    learned = FitQuality(36.0, 36, learned_repeatability=0.089)
    assert learned.statement.startswith("ok: χ²/dof = 1 for 36 dof")
    assert "by construction" in learned.statement and "0.089" in learned.statement
    undefined = FitQuality(0.0, 0)
    assert undefined.statement.startswith("undefined") and not undefined.poor
    assert undefined.sigma_factor == 1.0
    assert set(poor.as_json()) == {"chi2_dof", "dof", "chi2_p_value", "poor_fit", "fit_quality"}


def _generative_replicate(scene, rows, truth, scales, rng):
    """Rows of the bundled layout with ln R = Eq. (7) at ``truth`` plus the generative model's
    noise, written out here from its definition (error_model.py's docstring): each row's own
    σ_i, the repeatability, one effect per physical sample and one calibration factor per
    series; ``scales`` = (σ_rep, τ)."""
    from dataclasses import replace

    from brdf_infer.error_model import value_sigma
    from brdf_infer.synthetic import synthetic_measurements

    exact = synthetic_measurements(scene, rows, truth)
    repeatability, tau = scales
    samples = {name: rng.normal(0.0, tau) for name in set(rows.sample)}
    series = {name: rng.normal(0.0, scene.errors.calibration_rel) for name in set(rows.series)}
    noise = (
        rng.normal(0.0, value_sigma(scene.errors, rows))
        + rng.normal(0.0, repeatability, len(rows))
        + np.array([samples[name] for name in rows.sample])
        + np.array([series[name] for name in rows.series])
    )
    return replace(exact, reflectance=exact.reflectance * np.exp(noise))


def _no_angle_errors(scene):
    from dataclasses import replace

    return replace(scene, errors=replace(scene.errors, propagate_angles=False))


@pytest.mark.parametrize(
    ("replicates", "planted"), [(6, 1.0), pytest.param(120, None, marks=pytest.mark.slow)]
)
def test_a_learned_repeatability_is_judged_by_what_the_error_model_gives(lya, replicates, planted):
    """With σ_rep learned, χ²/dof is 1 by construction and a fit is poor when its Paule–Mandel
    σ_rep is beyond what the scene's error model gives (prior predictive p < 0.001). Data from
    that model at the bundled layout (Eq. 7 at uv-paper, σ_rep and the sample scale τ drawn
    from their half-normal priors, per-series calibration, angle errors off), each fitted by
    least squares: none is called poor and (slow, 120 fits) their p-values are uniform
    (Kolmogorov–Smirnov p > 0.001); planted: σ_rep = 1.0, ten times its prior scale, is
    always poor."""
    from scipy import stats

    from brdf_infer.lsq import fit_lsq
    from brdf_infer.params import UV_PAPER

    scene, rows = lya
    scene = _no_angle_errors(scene)
    rng = np.random.default_rng(11)
    p_values = []
    for _ in range(replicates):
        scales = np.abs(rng.normal(0.0, [0.1, 0.2]))
        data = _generative_replicate(scene, rows, UV_PAPER, scales, rng)
        fit = fit_lsq(scene, data, starts=4, init=UV_PAPER)
        quality = FitQuality(fit.cost, 36, fit.repeatability, fit.repeatability_p_value)
        assert not quality.poor and quality.statement.startswith("ok:"), quality.statement
        p_values.append(fit.repeatability_p_value)
    if replicates >= 100:
        assert stats.kstest(p_values, "uniform").pvalue > 1e-3, sorted(p_values)
    if planted is not None:
        data = _generative_replicate(scene, rows, UV_PAPER, (planted, 0.1), rng)
        fit = fit_lsq(scene, data, starts=4, init=UV_PAPER)
        quality = FitQuality(fit.cost, 36, fit.repeatability, fit.repeatability_p_value)
        assert quality.poor and fit.repeatability_p_value < POOR_P_VALUE
        assert quality.statement.startswith("poor: χ²/dof = 1 for 36 dof")
        assert "more than the scene's error model gives its data" in quality.statement


def test_paule_mandel_of_many_sets_is_each_sets_own():
    from brdf_infer._reweighting import paule_mandel_many

    rng = np.random.default_rng(5)
    variances = rng.uniform(0.001, 0.01, 30)
    residuals = rng.normal(0.0, 0.15, (8, 30)) * rng.uniform(0.05, 2.0, (8, 1))
    many = paule_mandel_many(residuals, variances, 25)
    one = [paule_mandel(r, variances, 25) for r in residuals]
    assert many == pytest.approx(one, rel=1e-12, abs=1e-15)
