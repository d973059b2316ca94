"""What a run's answer rests on: the physical prior, what carries each headline width, what the
data taught, and the published reference values (summary.json "width", "learned",
"reference")."""

from __future__ import annotations

import dataclasses
import json
import math

import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats
from scipy.special import logsumexp

from brdf_infer.errors import BadInputError
from brdf_infer.model import ENERGY_THETA_I_DEG, conserves_energy, log_tis
from brdf_infer.model.params import (
    PAPER_CONSTANTS,
    PARAM_NAMES,
    PARAMETER_SETS,
    Params,
    with_dphi_scale,
)
from brdf_infer.posterior import build_posterior_model, prior_draws, run_posterior
from brdf_infer.posterior._power_scaling import log_likelihood_draws
from brdf_infer.posterior._width import (
    _scale_marginal,
    smoothed_log_weights,
    weighted_interval,
)
from brdf_infer.scene import load_scene, parse_scene
from brdf_infer.verdict import answer_facts, posterior_verdict
from tests.helpers import MC_BOUND, REDUCED_NUTS, SUITE_WARMUP


def _params(draws: dict) -> Params:
    return Params(*(jnp.asarray(draws[name]) for name in PARAM_NAMES))


# ------------------------------------------------------------------ the physical prior


@pytest.mark.full
def test_the_physical_prior_has_no_coating_that_scatters_more_than_it_receives(lya):
    model = build_posterior_model(*lya)
    draws = prior_draws(model, 3000, seed=5)
    # independently of the check's grid and nodes: every 0.5° from 0 to 85°, 64 nodes, each
    # draw at its own out-of-plane width
    widths = with_dphi_scale(PAPER_CONSTANTS, jnp.asarray(draws["dphi_scale"]))
    fine = np.asarray(log_tis(jnp.arange(0.0, 85.01, 0.5), _params(draws), False, widths))
    assert np.exp(fine.max()) < 0.99  # the check keeps 0.95; peaks between its angles add < 4 %
    # the untruncated priors do put mass there (so the truncation is what removes it)
    import jax
    from numpyro.infer import Predictive

    raw = Predictive(model, num_samples=3000)(jax.random.PRNGKey(5), mode="simulate")
    above = np.mean(np.asarray(log_tis(jnp.array([70.0]), _params(raw)))[:, 0] > 0)
    assert 0.25 < above < 0.42  # 33 % of 20,000 draws when measured


@pytest.mark.full
def test_the_posterior_density_is_zero_beyond_energy_conservation(lya):
    from numpyro.infer.util import log_density

    model = build_posterior_model(*lya, reparametrise=False)
    base = PARAMETER_SETS["uv-paper"]
    assert bool(conserves_energy(base))
    bright = base._replace(brdf0=base.brdf0 * 40.0)  # π·BRDF0 ≈ 1.4: TIS > 1 everywhere
    assert not bool(conserves_energy(bright))

    def joint(p: Params) -> float:
        sites = {
            "log_brdf0": math.log(p.brdf0),
            "b1": p.a1 * 90**2,
            "b2": p.a2 * 90 ** (1 + p.alpha),
            "b3": p.a3 * 90 ** (2 + p.alpha),
            "alpha": p.alpha,
            "t_s0": p.theta_s0 / 90.0,
            "log_dphi_scale": 0.0,
            "sample_sd": 0.03,
            "repeatability": 0.02,
        }
        return float(log_density(model, (model.data,), {}, sites)[0])

    assert np.isfinite(joint(base))
    assert joint(bright) == -np.inf


def test_the_check_angles_cover_the_stated_range():
    assert ENERGY_THETA_I_DEG[0] == 0.0 and ENERGY_THETA_I_DEG[-1] == 85.0


# ------------------------------------------------------------------ width: the machinery


def test_a_weighted_interval_with_equal_weights_is_the_empirical_one():
    values = np.random.default_rng(0).normal(size=20_000)
    low, high = weighted_interval(values, np.zeros(values.size))
    np.testing.assert_allclose([low, high], np.quantile(values, [0.025, 0.975]), atol=2e-3)


def test_reweighting_a_normal_to_a_narrower_one_gives_its_interval():
    """Draws of N(0, 1) reweighted by N(0, 0.5²)/N(0, 1): the 95 % interval of N(0, 0.5²)."""
    rng = np.random.default_rng(1)
    values = rng.normal(size=40_000)
    ratio = stats.norm.logpdf(values, scale=0.5) - stats.norm.logpdf(values)
    log_weights, k_hat = smoothed_log_weights(ratio)
    low, high = weighted_interval(values, log_weights)
    assert k_hat < 0.5
    np.testing.assert_allclose([low, high], [-0.98, 0.98], atol=0.03)
    # the other way round (a wider target) the weights are heavy-tailed, and k̂ says so
    _, k_wide = smoothed_log_weights(-ratio * 3.0)
    assert k_wide > 0.7


def test_the_sample_scale_is_integrated_out_over_its_prior(nuts_run, lya):
    """The Rao–Blackwellised proposal ∫ p(y | θ, τ) p(τ) dτ at posterior draws of θ, against
    a dense quadrature over the whole half-line: the trapezoidal rule in ln τ on 2¹³ steps from
    τ = 1e-8 (below, the integrand is bounded and the interval 1e-8 long) to 2 (10 prior
    sd), the integrand at every node from one batched evaluation (scipy's adaptive ``quad``
    took ≈ 800 one-draw evaluations, 15-20 s); halving the step changes it by < 1e-6."""
    scene, measurements = lya
    model = build_posterior_model(scene, measurements)
    posterior = nuts_run.idata.posterior
    every = {name: np.asarray(posterior[name]).reshape(-1) for name in posterior.data_vars}
    flat = {k: v for k, v in every.items() if v.ndim == 1}
    ours = _scale_marginal(model, flat, "sample_sd")
    prior_scale = scene.errors.sample_sd_prior
    log_tau = np.linspace(math.log(1e-8), math.log(2.0), 2**13 + 1)
    tau = np.exp(log_tau)
    # ln of the integrand in ln τ: ln p(y | θ, τ) + ln p(τ) + ln τ (dτ = τ d ln τ)
    log_prior = np.log(2.0) + stats.norm.logpdf(tau, scale=prior_scale) + log_tau

    def trapezoid(log_values, step: int) -> float:
        nodes = log_values[::step]
        weights = np.full(nodes.size, step * (log_tau[1] - log_tau[0]))
        weights[[0, -1]] /= 2
        return float(logsumexp(nodes, b=weights))

    for index in (0, 1234, 2500, 3999):
        one = {k: np.repeat(v[index], tau.size) for k, v in flat.items()}
        log_values = log_likelihood_draws(model, {**one, "sample_sd": tau}) + log_prior
        fine, coarse = trapezoid(log_values, 1), trapezoid(log_values, 2)
        assert abs(fine - coarse) < 1e-6, (index, fine, coarse)
        # 2e-4 measured; 8e-3 when the nodes spanned the extreme τ draws (down to 4e-6)
        np.testing.assert_allclose(ours[index], fine, atol=5e-4)


# ------------------------------------------------------------------ a run's records


def test_a_run_says_what_carries_its_width_what_it_learned_and_where_the_article_lies(nuts_run):
    summary = nuts_run.summary
    width = summary["width"]
    assert {"tis_70deg", "pi_brdf0"} <= set(width)
    for name in ("tis_18deg", "tis_80deg"):  # the scene's [outputs] angles
        assert name in width
    tis = width["tis_70deg"]
    assert tis["lo95"] == pytest.approx(summary["tis_70deg"]["lo95"], rel=1e-9)
    assert 0 < tis["mcse_lo95"] < 0.05 * (tis["hi95"] - tis["lo95"])
    assert tis["prior"]["p_above_1"] == 0.0
    assert set(tis["without"]) == {"calibration", "sample_effect", "angle_errors", "out_of_plane"}
    for quantity, entry in width.items():
        for name, alternative in entry["without"].items():
            # nuts_run does not refit (refit=False); the main job's refits: tests/test_cli.py
            assert alternative["method"] == (
                "psis" if alternative["pareto_k"] <= 0.7 else "unreliable"
            ), (quantity, name)
            share = alternative["variance_share"]
            if alternative["method"] == "unreliable":
                assert alternative["lo95"] is None and share is None
                continue
            # no negative share anywhere: a variance share, or none where the
            # alternative's interval is wider
            assert (share is None) == (alternative["ratio"] > 1.0), (quantity, name)
            assert share is None or 0.0 <= share <= 1.0
            assert alternative["mcse_lo95"] > 0 and alternative["mcse_hi95"] > 0
            assert alternative["delta_elpd_se"] >= 0
    # π·BRDF0 is Eq. (7)'s BRDF0: the out-of-plane width does not touch it, and the per-series
    # calibration carries most of its variance (measured 0.60)
    calibration = width["pi_brdf0"]["without"]["calibration"]
    assert calibration["variance_share"] > 1.0 / 3.0
    assert width["pi_brdf0"]["without"]["out_of_plane"]["variance_share"] == pytest.approx(
        0.0, abs=1e-9
    )
    learned = summary["learned"]
    assert set(learned) == {*PARAM_NAMES, "dphi_scale", "sample_sd", "repeatability"}
    assert learned["brdf0"]["learned"] and learned["repeatability"]["learned"]
    assert not learned["theta_s0"]["learned"]  # no row below θs0 (the lsq warning)
    assert learned["theta_s0"]["words"].startswith("set by its prior (truncated normal, sd 6")
    references = {r["quantity"]: r for r in summary["reference"]}
    assert references["tis_70deg"]["value"] == 0.058
    for entry in references.values():
        assert entry["place"] in ("inside", "outside", "at the edge")
        assert entry["inside95"] == (entry["place"] == "inside")
        assert 0 < entry["quantile_mcse"] < 0.01
    draws = np.asarray(nuts_run.idata.posterior["brdf0"]).reshape(-1)
    assert references["brdf0"]["posterior_quantile"] == pytest.approx(np.mean(draws < 0.0114))
    facts = " ".join(summary["verdict"]["facts"])
    assert "the calibration carries" in facts and "of π·BRDF0's 95 % interval variance" in facts
    assert "out-of-plane width's uncertainty carries" in facts
    # facts are no failures; nuts_run does not refit, so a row whose k̂ exceeds 0.7 by chance
    # (series II, 45°/60°: 0.7-1.0 from run to run) stays one (tests/test_loo_refit.py)
    assert summary["verdict"]["ok"] == (summary["predictive"]["pareto_k_high"] == 0)
    assert all("Pareto k" in line for line in summary["verdict"]["lines"])


def test_a_reference_within_its_quantiles_mc_error_of_the_cut_is_at_the_edge():
    """The article's π·BRDF0 and BRDF0 (one quantity) fell either side of 0.025 by chance
    (0.02525 "inside", 0.021 "outside"): within two Monte Carlo errors of the cut neither is
    called."""
    from brdf_infer.posterior._reference import quantile_place

    error = math.sqrt(0.025 * 0.975 / 3000)  # ≈ 0.0029 from 3000 effective draws
    assert quantile_place(0.02525, error) == quantile_place(0.021, error) == "at the edge"
    assert quantile_place(0.009, error) == "outside" and quantile_place(0.5, error) == "inside"
    assert quantile_place(0.99, error) == "outside"


@pytest.mark.slow  # ≈ 15 s: a second NUTS run
def test_psis_and_a_new_posterior_agree_on_the_width_without_the_calibration(nuts_run, lya):
    """The reweighted interval against a NUTS run of the variant itself (the sound case)."""
    scene, measurements = lya
    variant = dataclasses.replace(
        scene, errors=dataclasses.replace(scene.errors, calibration="none")
    )
    run = run_posterior(variant, measurements, progress=False, seed=3, **REDUCED_NUTS)
    ours = nuts_run.summary["width"]["tis_70deg"]["without"]["calibration"]
    theirs = run.summary["width"]["tis_70deg"]
    # each end within MC_BOUND combined Monte Carlo standard errors (each record's own:
    # Kish's ESS of the weights for the reweighted one, the draws' ESS for the run's)
    for end in ("lo95", "hi95"):
        error = math.hypot(ours[f"mcse_{end}"], theirs[f"mcse_{end}"])
        assert abs(ours[end] - theirs[end]) < MC_BOUND * error, (end, ours[end], theirs[end])


@pytest.mark.full
def test_a_one_sample_scene_names_its_sample_effect_set_by_its_prior(tmp_path, lya):
    rows = [
        line
        for line in (lya[0].measurements_path).read_text().splitlines()
        if line.startswith(("series", "II,"))
    ]
    (tmp_path / "one.csv").write_text("\n".join(rows) + "\n")
    text = (
        'name = "one-sample"\nmeasurements = "one.csv"\n'
        "[series.II]\naperture_diameter_mm = 7.5\naperture_distance_mm = 110.0\n"
    )
    (tmp_path / "one.scene.toml").write_text(text)
    scene = load_scene(tmp_path / "one.scene.toml")
    # 4 × 1000 draws: the variance share's Monte Carlo error with 2 × 500 was 0.10–0.12 for a
    # share of 0.39–0.56 (two draws of the chains, 3.7 and 4.6 errors from 0), too coarse to
    # tell it from 0 at MC_BOUND; a one-sample structure's program is compiled for this alone
    run = run_posterior(
        scene,
        scene.load_measurements(),
        progress=False,
        out=tmp_path / "run",
        chains=4,
        warmup=SUITE_WARMUP,
        draws=1000,
    )
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    sample = summary["learned"]["sample_sd"]
    assert not sample["learned"] and abs(sample["contraction"]) < 0.3
    assert sample["words"] == "set by its prior (half-normal, scale 0.2)"
    # the prior-set sample scale widens the band: its variance share clear of 0 by its Monte
    # Carlo error
    effect = summary["width"]["tis_70deg"]["without"]["sample_effect"]
    assert effect["variance_share"] > MC_BOUND * effect["variance_share_mcse"], effect
    assert any(
        "sample-to-sample scale is set by its prior" in f for f in summary["verdict"]["facts"]
    )
    assert run.summary["reference"] == []


# ------------------------------------------------------------------ scene and verdict


def test_reference_values_are_checked_when_the_scene_loads(tmp_path):
    base = (
        'name = "x"\nmeasurements = "m.csv"\n'
        "[series.I]\naperture_diameter_mm = 7.2\naperture_distance_mm = 103.8\n"
    )

    def parse(extra: str):
        import tomllib

        return parse_scene(tomllib.loads(base + extra), tmp_path / "x.toml")

    with pytest.raises(BadInputError) as error:
        parse('[reference.tis_95deg]\nvalue = 0.1\nsource = "a"\n')
    assert error.value.field == "reference.tis_95deg"
    with pytest.raises(BadInputError) as error:
        parse("[reference.pi_brdf0]\nvalue = 0.1\n")
    assert error.value.field == "reference.pi_brdf0.source"
    with pytest.raises(BadInputError):
        parse('[reference.pi_brdf0]\nvalue = 0.1\nsource = "a"\nunit = "%"\n')
    scene = parse('[reference."tis_12.5deg"]\nvalue = 0.04\nsource = "lab"\n')
    assert scene.references[0].quantity == "tis_12.5deg"


def test_the_verdict_names_every_row_with_a_high_pareto_k():
    summary = {
        "diagnostics": {"failures": []},
        "predictive": {
            "pareto_k_high": 1,
            "pareto_k_rows": [
                {
                    "row": 40,
                    "series": "II",
                    "sample": "40x40",
                    "theta_i_deg": 80.0,
                    "theta_s_deg": 85.0,
                    "k": 0.74,
                }
            ],
        },
        "pi_brdf0": None,
    }
    verdict = posterior_verdict(summary, {}, [])
    assert not verdict.ok
    assert "series II, sample 40x40, θi 80°, θs 85° (k 0.74)" in verdict.text


def test_an_assumption_carrying_a_third_of_a_headline_variance_is_a_fact_not_a_failure():
    """A variance share (1 − ratio², sources in quadrature) above a third is a fact; a wider
    alternative (ratio > 1) carries no share and is no fact, and no share is ever negative."""

    def without(ratio):
        share = None if ratio > 1 else 1 - ratio**2
        return {"ratio": ratio, "variance_share": share, "words": "the calibration"}

    summary = {
        "width": {
            "tis_70deg": {"without": {"calibration": without(0.6)}},
            "pi_brdf0": {"without": {"calibration": without(1.2)}},
        }
    }
    facts = answer_facts(summary)
    assert facts == [
        "the calibration carries 64 % of TIS(70°)'s 95 % interval variance (in quadrature)"
    ]
    summary["width"]["tis_70deg"]["without"]["calibration"] = without(0.82)
    assert answer_facts(summary) == []  # 1 − 0.82² = 33 % is not more than a third


def test_without_a_refit_an_unreliable_variant_has_no_interval(nuts_run, lya):
    """Batch and a study's extra posteriors do not refit: a variant whose weights have
    k̂ > 0.7 (on lya, the angle errors) is reported with its k̂ and no interval (JSON null)."""
    from brdf_infer.posterior._width import headline_draws, width_attribution

    model = build_posterior_model(*lya)
    posterior = nuts_run.idata.posterior
    sites = {name: np.asarray(posterior[name]) for name in posterior.data_vars}
    physical = {name: sites[name].reshape(-1) for name in model.family.parameters}
    headline = headline_draws(model.family, physical, [70.0])
    width = width_attribution(model, lya[1], sites, headline, headline, refit=None)
    angles = width["tis_70deg"]["without"]["angle_errors"]
    assert angles["pareto_k"] > 0.7 and angles["method"] == "unreliable"
    assert angles["lo95"] is None and angles["ratio"] is None
    calibration = width["tis_70deg"]["without"]["calibration"]
    assert calibration["ratio"] == pytest.approx(
        nuts_run.summary["width"]["tis_70deg"]["without"]["calibration"]["ratio"], rel=1e-9
    )
    assert answer_facts({"width": width})[0].startswith("the out-of-plane width's uncertainty")
