"""Exact leave-one-out by refit (:mod:`brdf_infer.posterior._loo_refit`) where PSIS-LOO's k̂
exceeds 0.7, and the verdict that follows from it."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import logsumexp

from brdf_infer.posterior import (
    build_posterior_model,
    exact_loo_rows,
    loo_terms,
    run_nuts,
)
from brdf_infer.posterior._loo import ExactTerm, LeaveOneOut, psis_loo
from brdf_infer.posterior._loo_refit import MAX_REFIT_ROWS
from brdf_infer.posterior._run import predictive_checks
from brdf_infer.verdict import answer_facts, posterior_verdict
from tests.helpers import REDUCED_NUTS


@pytest.fixture(scope="module")
def lya_draws(lya):
    scene, measurements = lya
    model = build_posterior_model(scene, measurements)
    draws = run_nuts(model, seed=0, progress=False, **REDUCED_NUTS)
    log_lik, cdf = loo_terms(model, draws.sites)
    return model, draws, psis_loo(log_lik, cdf, 1.0)  # reff 1: the smoothing's tail length


@pytest.mark.full
def test_a_refit_without_a_row_gives_its_psis_term_where_psis_is_reliable(lya_draws):
    """Where k̂ is below its limit PSIS-LOO is reliable, so the refit's exact term must agree
    with it within their Monte Carlo error (each estimate's standard error: PSIS's by the delta
    method over its smoothed weights, the refit's from the ESS of its draws; a fixed seed does
    not make NUTS reproducible across CPUs, so the bound is 4.5 combined standard errors); the
    planted fault (the row not left out: the full posterior's ln mean p(yᵢ | y₋ᵢ, θ)) lies
    p_loo,ᵢ above it and must not. The row: the one with the largest p_loo,ᵢ among the reliable
    ones (row 41 on every seed measured, p_loo,ᵢ 1.13–1.18 against ≤ 0.67 for the next)."""
    model, draws, loo = lya_draws
    reliable = np.flatnonzero(loo.pareto_k < loo.limit)
    row = int(reliable[np.argmax((loo.lppd_i - loo.elpd_i)[reliable])])
    pareto_k = np.zeros_like(loo.pareto_k)
    pareto_k[row] = 1.0  # ask for this row alone
    (exact,) = exact_loo_rows(model, draws, pareto_k, 0.7).values()
    bound = 4.5 * np.hypot(exact.mcse, loo.mcse_i[row])
    # measured over 6 NUTS seeds: differences sd 0.036, combined standard error 0.035-0.045
    assert 0.0 < bound < 0.3, bound
    assert abs(exact.elpd - loo.elpd_i[row]) < bound, (exact, loo.elpd_i[row], bound)
    planted = loo.lppd_i[row] - loo.elpd_i[row]
    assert planted > 2 * bound, (planted, bound)  # the planted fault fails the same bound
    assert abs(exact.pit - loo.pit[row]) < 0.05  # PIT ≈ 0.988, MC error < 1e-3


def test_the_mc_errors_of_loo_terms_are_the_spread_of_their_estimates():
    """The two standard errors the test above rests on, against the spread of many estimates
    of a known mean: ln mean of independent lognormal p (the refit's), and self-normalised
    importance sampling of E_p[p] with weights ∝ 1/p (PSIS-LOO's)."""
    from brdf_infer.posterior._loo import log_mean_mcse, psis_mcse

    rng = np.random.default_rng(5)
    terms = rng.normal(0.0, 0.8, (400, 4, 500))  # 400 repeats of 4 chains × 500 draws
    estimates = [np.log(np.mean(np.exp(t))) for t in terms]
    errors = [log_mean_mcse(t) for t in terms]
    assert np.median(errors) == pytest.approx(np.std(estimates), rel=0.1)
    log_terms = rng.normal(0.0, 0.5, (400, 2000))
    log_weights = -log_terms - logsumexp(-log_terms, axis=1, keepdims=True)
    estimates = logsumexp(log_weights + log_terms, axis=1)
    errors = psis_mcse(log_weights, log_terms, 1.0)
    assert np.median(errors) == pytest.approx(np.std(estimates), rel=0.15)


def test_more_rows_than_the_cap_are_not_refitted(lya_draws):
    model, draws, loo = lya_draws
    pareto_k = np.zeros_like(loo.pareto_k)
    pareto_k[: MAX_REFIT_ROWS + 1] = 1.0
    assert exact_loo_rows(model, draws, pareto_k, 0.7) == {}
    assert exact_loo_rows(model, draws, np.zeros_like(loo.pareto_k), 0.7) == {}


def test_a_refitted_row_leaves_the_failures_and_its_exact_term_enters_the_elpd(lya):
    """predictive_checks with a refitted row: counted out of pareto_k_high and pareto_k_rows,
    named in loo_refit_rows, its exact term in elpd_loo, p_loo = lppd − elpd, se over the
    new terms; the verdict passes and states it."""
    _, measurements = lya
    rows = len(measurements)
    loo = LeaveOneOut(
        elpd_loo=-float(rows),
        se=0.0,
        p_loo=0.5 * rows,
        pareto_k=np.r_[0.95, 0.8, np.zeros(rows - 2)],
        pit=np.full(rows, 0.5),
        elpd_i=np.full(rows, -1.0),
        lppd_i=np.full(rows, -0.5),
    )
    checks = predictive_checks(loo, measurements, {0: ExactTerm(-3.0, 0.9, 0.01)})
    assert checks["pareto_k_high"] == 1  # row 1, not refitted
    assert [r["row"] for r in checks["pareto_k_rows"]] == [1]
    assert [(r["row"], r["elpd_exact"]) for r in checks["loo_refit_rows"]] == [(0, -3.0)]
    assert checks["elpd_loo"] == pytest.approx(-3.0 - (rows - 1))
    assert checks["p_loo"] == pytest.approx(-0.5 * rows - checks["elpd_loo"])
    terms = np.r_[-3.0, np.full(rows - 1, -1.0)]
    assert checks["se"] == pytest.approx(np.sqrt(rows * np.var(terms)))
    assert checks["loo_pit"][0] == 0.9
    summary = {"diagnostics": {"failures": []}, "predictive": checks, "pi_brdf0": None}
    verdict = posterior_verdict(summary, {}, [])
    assert not verdict.ok and "Pareto k > 0.7" in verdict.lines[0]  # row 1 still fails
    exact = {0: ExactTerm(-3.0, 0.9, 0.01), 1: ExactTerm(-1.2, 0.4, 0.01)}
    checks = predictive_checks(loo, measurements, exact)
    verdict = posterior_verdict({**summary, "predictive": checks}, {}, [])
    assert verdict.ok and "2 influential measurement(s)" in " ".join(verdict.facts)


def test_a_refitted_row_is_a_fact_of_the_verdict_not_a_failure():
    row = {"row": 30, "series": "II", "sample": "40x40", "theta_i_deg": 45.0}
    row |= {"theta_s_deg": 60.0, "k": 0.96, "elpd_exact": -0.13}
    facts = answer_facts({"predictive": {"loo_refit_rows": [row]}})
    assert facts == [
        "1 influential measurement(s), Pareto k > 0.7, their leave-one-out terms from a refit "
        "without them: series II, sample 40x40, θi 45°, θs 60° (k 0.96)"
    ]
