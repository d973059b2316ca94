"""A variant's posterior by importance sampling from a run's draws
(:func:`brdf_infer.posterior._laplace.importance_refit`): the width record's variants and the
exact leave-one-out rows start there and sample anew only where Pareto k̂ refuses it."""

from __future__ import annotations

import numpy as np
import pytest

from brdf_infer._internal import arviz as az
from brdf_infer.posterior import Refused, build_posterior_model, run_nuts
from brdf_infer.posterior import _laplace as laplace
from brdf_infer.posterior._bands import draws_physical
from brdf_infer.posterior._width import ASSUMPTIONS, headline_draws, variant_model
from tests.helpers import (
    MC_BOUND,
    REDUCED_NUTS,
    log_sd_se,
    mcmc_quantile_se,
    quantile_se,
    resampled_ess,
)


def assumption(name: str):
    return next(a for a in ASSUMPTIONS if a.name == name)


@pytest.fixture(scope="module")
def lya_runs(lya):
    """The bundled scene's NUTS draws, and those of its variant without the calibration
    (a zero scale: the same program) by a NUTS run of its own."""
    scene, measurements = lya
    model = build_posterior_model(scene, measurements)
    run = run_nuts(model, seed=0, progress=False, **REDUCED_NUTS)
    variant = variant_model(model, measurements, assumption("calibration"))
    own = run_nuts(variant, seed=1, progress=False, program=run.program, **REDUCED_NUTS)
    return model, run, variant, own


def tis_draws(draws, model) -> np.ndarray:
    """π·BRDF0 of every draw, (chains, draws) [fraction]: the headline the calibration carries
    most of (TIS(70°)'s width is mostly the out-of-plane width's prior, which both samplings
    share and which would hide what they differ in)."""
    values = headline_draws(model.family, draws_physical(draws.sites, model.family), [70.0])
    return values["pi_brdf0"].reshape(np.shape(draws.sites["brdf0"]))


def disagreements(sampled, own, model) -> list[str]:
    """Where an importance refit's π·BRDF0 disagrees with the variant's own NUTS run beyond
    :data:`MC_BOUND` combined Monte Carlo standard errors: an end of the 95 % interval, or the
    spread (ln sd: its error √((κ − 1)/4 ESS) is a fifth of a 95 % width's, so it sees a
    width 20 % off where the ends cannot). The refit's errors from Kish's ESS of its weights
    with the resampling's noise added, NUTS's from the ESS at each quantile and of the
    draws."""
    ours, theirs = tis_draws(sampled, model), tis_draws(own, model)
    ess = resampled_ess(sampled.extra["ess"], ours.size)
    found = []
    for end, prob in (("lo", 0.025), ("hi", 0.975)):
        error = np.hypot(quantile_se(ours, prob, ess), mcmc_quantile_se(theirs, prob))
        gap = abs(np.quantile(ours, prob) - np.quantile(theirs, prob))
        if gap > MC_BOUND * error:
            found.append(end)
    error = np.hypot(log_sd_se(ours, ess), log_sd_se(theirs, float(az.ess(theirs))))
    if abs(np.log(np.std(ours) / np.std(theirs))) > MC_BOUND * error:
        found.append("sd")
    return found


def refit(run, variant):
    """An importance refit of 2 × 2000 draws (the answer records' are 2 × 500: more draws
    here give the comparisons above the power to see the planted faults)."""
    return laplace.importance_refit(
        run, variant, variant.data, chains=2, count=2000, seed=0, proposals=16000
    )


@pytest.mark.full
def test_the_variant_without_the_calibration_by_importance_agrees_with_its_own_nuts(lya_runs):
    """The π·BRDF0 interval, end by end and its spread, within Monte Carlo error of the
    variant's own NUTS run (:func:`disagreements`)."""
    _, run, variant, own = lya_runs
    sampled = refit(run, variant)
    assert not isinstance(sampled, Refused), sampled
    assert sampled.extra["pareto_k"] <= laplace.pareto_k_limit(4000)
    assert sampled.extra["ess"] > 500
    assert sampled.sites["brdf0"].shape == (2, 2000)
    assert disagreements(sampled, own, variant) == []


@pytest.mark.full
def test_the_refit_without_its_weights_is_the_run_and_disagrees(lya_runs, monkeypatch):
    """Planted fault: the importance weights ignored (uniform, k̂ 0): the proposal is kept
    and its draws come as they are, the run's Student-t: the run's own spread, wider than the
    variant's (the calibration carries about 60 % of π·BRDF0's variance); the comparison above
    must see it."""
    _, run, variant, own = lya_runs
    monkeypatch.setattr(
        laplace.az, "psislw", lambda raw: (np.full_like(raw, -np.log(raw.size)), 0.0)
    )
    assert disagreements(refit(run, variant), own, variant) != []


@pytest.fixture(scope="module")
def without_angle_errors(lya_runs, lya):
    """The variant without the angle errors and its own NUTS draws: their latent standard
    normals leave the likelihood and the whitened coefficients' metric changes, so the
    variant's posterior lies far from the run's draws (the first trial's k̂ ≈ 8)."""
    model, run, _, _ = lya_runs
    far = variant_model(model, lya[1], assumption("angle_errors"))
    return far, run_nuts(far, seed=1, progress=False, program=run.program, **REDUCED_NUTS)


@pytest.mark.full
def test_a_variant_far_from_the_run_is_reached_by_newton_steps(lya_runs, without_angle_errors):
    """The far variant's π·BRDF0 within Monte Carlo error of its own NUTS run."""
    _, run, _, _ = lya_runs
    far, own = without_angle_errors
    sampled = refit(run, far)
    assert not isinstance(sampled, Refused), sampled
    assert disagreements(sampled, own, far) == []


@pytest.mark.full
def test_without_the_newton_steps_the_far_variant_is_refused(lya_runs, without_angle_errors):
    """Planted fault: no move to the variant's mode; the moment adaptations alone end at
    k̂ ≈ 1.6, which the threshold refuses (the caller then samples the variant anew)."""
    _, run, _, _ = lya_runs
    far, _ = without_angle_errors
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(laplace.LaplaceProgram, "newton_proposal", lambda self, data, start: None)
        assert "Pareto k" in refit(run, far).reason


def test_a_variant_of_another_space_is_refused(lya_runs, lya):
    """Without the sample effect the variant has no scale τ: refused before any evaluation."""
    model, run, _, _ = lya_runs
    other = variant_model(model, lya[1], assumption("sample_effect"))
    assert refit(run, other) == Refused("the variant's unconstrained space is not the run's")


def test_a_run_without_unconstrained_draws_is_refused(lya_runs):
    model, run, _, _ = lya_runs
    bare = laplace.Draws(run.sites, run.stats, "emcee", run.settings, {})
    assert refit(bare, model) == Refused("the run kept no unconstrained draws")


def test_the_sample_size_sets_the_pareto_k_threshold():
    assert laplace.pareto_k_limit(1000) == pytest.approx(2 / 3)
    assert laplace.pareto_k_limit(4000) == laplace.PARETO_K_LIMIT


@pytest.mark.full
def test_the_answer_records_of_a_large_table_read_thinned_draws(lya_runs, lya, monkeypatch):
    """On a table beyond LOO_VALUES the width and learned records read the draws PSIS-LOO
    reads (here forced to 250 a chain on the bundled rows): the run's own intervals stay
    those of every draw, and each variant's ratio moves by Monte Carlo error only (measured
    at most 0.05 from the records of every draw, typically 0.02)."""
    from brdf_infer.posterior import _answer, _results

    model, run, _, _ = lya_runs
    angles = lya[0].band_theta_i_deg(lya[1])
    every = _answer.answer_records(model, lya[1], run, angles, True, 0, refit=False)
    monkeypatch.setattr(_results, "LOO_VALUES", 4 * 250 * len(lya[1]))
    thinned = _answer.answer_records(model, lya[1], run, angles, True, 0, refit=False)
    for name, entry in every["width"].items():
        other = thinned["width"][name]
        assert (other["lo95"], other["hi95"]) == (entry["lo95"], entry["hi95"])
        for assumption, variant in entry["without"].items():
            if variant["ratio"] is not None:
                ratio = other["without"][assumption]["ratio"]
                assert abs(ratio - variant["ratio"]) < 0.1, (name, assumption)
