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


def test_a_learned_repeatability_is_judged_against_its_prior():
    """With σ_rep learned, χ²/dof is 1 by construction; the fit is poor when the Paule–Mandel
    σ_rep lies beyond its half-normal prior's tail at POOR_P_VALUE (3.29 scales). Simulated
    on 36 rows (36 dof, the parameters known) with rows' own σ of 0.02: σ_rep drawn from the
    prior (scale 0.1) is called poor at about the prior's tail rate (1.35e-3 measured on
    20,000: the estimate's own scatter, ≈ 1/√72 = 12 % relative, widens the tail a little;
    bound 2e-3, 2.5 binomial sd above), and a planted σ_rep of 5 scales always."""
    rng = np.random.default_rng(3)
    variance = 0.02**2

    def learned(residuals: np.ndarray) -> float:
        """Paule–Mandel with equal variances in closed form: s² = Σr²/dof − v."""
        return math.sqrt(max(float(np.sum(residuals**2)) / 36 - variance, 0.0))

    def quality(true_sd: float) -> FitQuality:
        residuals = rng.normal(0.0, math.sqrt(variance + true_sd**2), 36)
        s = learned(residuals)
        chi2 = float(np.sum(residuals**2 / (variance + s**2)))
        return FitQuality(chi2, 36, s, repeatability_prior_scale=0.1)

    residuals = rng.normal(0.0, 0.1, 36)  # the closed form is the bisection's answer
    assert paule_mandel(residuals, np.full(36, variance), 36) == pytest.approx(learned(residuals))
    right = [quality(abs(rng.normal(0.0, 0.1))) for _ in range(20_000)]
    rate = np.mean([q.poor for q in right])
    assert 0 < rate <= 2 * POOR_P_VALUE
    assert all(q.chi2_dof == pytest.approx(1.0) for q in right if q.learned_repeatability > 0)
    planted = [quality(0.5) for _ in range(200)]
    assert all(q.poor and q.statement.startswith("poor: χ²/dof = 1 for 36 dof") for q in planted)
    assert "times the scale of its prior (0.1" in planted[0].statement
    assert planted[0].repeatability_p_value < POOR_P_VALUE
    assert FitQuality(36.0, 36, 0.2, repeatability_prior_scale=0.1).statement.startswith("ok:")
    assert FitQuality(36.0, 36, 0.2).repeatability_p_value is None  # no prior: not judged
