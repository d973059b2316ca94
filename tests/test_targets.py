"""Which coating a band is for: the sample(s) measured, the coating, a new part
(:mod:`brdf_infer.posterior._targets`), and τ from another run of the coating."""

from __future__ import annotations

import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from brdf_infer.errors import BadInputError
from brdf_infer.model import family
from brdf_infer.model.params import UV_PAPER, params_to_dict
from brdf_infer.posterior import (
    QUESTIONS,
    build_posterior_model,
    chosen_target,
    target_log_factor,
)
from brdf_infer.posterior._targets import effect_moments, targets_record
from brdf_infer.scene import load_scene
from tests.helpers import (
    MC_BOUND,
    assert_allclose,
    mcmc_quantile_se,
    quantile_se,
    run_cli,
    series_ii_scene_file,
)
from tests.test_families import PHYSICAL

# ---------------------------------------------------------------- a sample effect is a factor


@pytest.mark.full
@pytest.mark.parametrize("name", ["strumik2024", *PHYSICAL])
def test_a_sample_effect_multiplies_the_brdf_and_the_tis_of_every_family(name):
    """e^u on every ln R of a sample is e^u on its BRDF everywhere and on its TIS: scaling a
    family's amplitudes (``ModelFamily.scaled``) by e^0.3 moves ln BRDF by 0.3 at every point
    of the hemisphere and multiplies the TIS by e^0.3."""
    member = family(name)
    physical = params_to_dict(UV_PAPER) if name == "strumik2024" else dict(PHYSICAL[name])
    physical = {k: jnp.asarray(v, float) for k, v in physical.items()}
    scaled = {k: jnp.asarray(v) for k, v in member.scaled(physical, 0.3).items()}
    rng = np.random.default_rng(0)
    theta_i, theta, phi = rng.uniform([0, 1, 0], [85, 89, 360], (40, 3)).T
    before = np.asarray(member.log_brdf(theta_i, theta, phi, physical))
    after = np.asarray(member.log_brdf(theta_i, theta, phi, scaled))
    assert_allclose(after - before, np.full(40, 0.3), rtol=0, atol=1e-12)
    ratio = float(member.tis(40.0, scaled)) / float(member.tis(40.0, physical))
    assert_allclose(ratio, np.exp(0.3), rtol=1e-9)


# ---------------------------------------------------------------- the conditional of u


def _three_sample_scene(folder: Path):
    """Three samples (one of a single row), two series with a calibration each, the angle
    errors off: then the rows' covariance is σ_i² + σ_rep² on the diagonal, τ² between rows of
    one sample, σ_cal² between rows of one series, which the dense check below writes out."""
    rows = ["series,sample,theta_i_deg,theta_s_deg,reflectance,reflectance_err"]
    rng = np.random.default_rng(4)
    for series, sample, count in (("A", "s1", 6), ("A", "s2", 5), ("B", "s2", 4), ("B", "s3", 1)):
        for k in range(count):
            value = 2e-4 * np.exp(rng.normal(0.0, 0.1))
            rows.append(
                f"{series},{sample},{10 + 12 * k:g},{5 + 9 * k:g},{value:.6e},{0.03 * value:.6e}"
            )
    (folder / "rows.csv").write_text("\n".join(rows) + "\n")
    geometry = "aperture_diameter_mm = 7.2\naperture_distance_mm = 103.8\n"
    (folder / "scene.toml").write_text(
        'name = "three"\nmeasurements = "rows.csv"\n'
        f"[series.A]\n{geometry}[series.B]\n{geometry}"
        "[errors]\npropagate_angles = false\ncalibration_rel = 0.05\n"
    )
    return load_scene(folder / "scene.toml")


def _dense_conditional(model, sites, k: int):
    """The conditional of the sample effects of draw ``k`` from the joint normal of (u, y)
    written out densely (independent of the low-rank factor): Cov(u, y) Σ⁻¹ r and
    τ² I − Cov(u, y) Σ⁻¹ Cov(y, u)."""
    names = list(model.sample_names)
    samples = np.array([names.index(s) for s in model.row_samples])
    series = np.asarray(model.row_series)
    tau = float(sites["sample_sd"][0, k])
    repeat = float(sites["repeatability"][0, k])
    sigma = np.asarray(model.data.noise.sigma_row)
    same_sample = samples[:, None] == samples[None, :]
    same_series = series[:, None] == series[None, :]
    cov_y = np.diag(sigma**2 + repeat**2) + tau**2 * same_sample + 0.05**2 * same_series
    cov_uy = tau**2 * (np.arange(len(names))[:, None] == samples[None, :])
    point = {name: np.asarray(values)[:, k : k + 1] for name, values in sites.items()}
    mean = np.asarray(model.draw_parts({n: v[0] for n, v in point.items()}).mean[0])
    residual = np.asarray(model.data.rows.log_reflectance) - mean
    gain = cov_uy @ np.linalg.inv(cov_y)
    return gain @ residual, tau**2 * np.eye(len(names)) - gain @ cov_uy.T


def _draws_near_truth(model, count: int, seed: int) -> dict[str, np.ndarray]:
    """``count`` parameter sets near the UV parameters with learned-scale values, as one
    chain of sites."""
    rng = np.random.default_rng(seed)
    values = {"dphi_scale": 1.0, **params_to_dict(UV_PAPER)}
    sites = {
        name: np.full((1, count), values[name]) * np.exp(rng.normal(0.0, 0.05, (1, count)))
        for name in model.family.parameters
    }
    sites["sample_sd"] = rng.uniform(0.02, 0.3, (1, count))
    sites["repeatability"] = rng.uniform(0.01, 0.1, (1, count))
    return sites


@pytest.mark.full
def test_the_sample_effects_conditional_is_the_dense_gaussian_conditional(tmp_path):
    """Mean and covariance of u | θ, y from the low-rank conjugate formula match the joint
    normal of (u, y) written out densely, for three samples (one of a single row) and two
    calibration groups at five parameter draws; a conditional that forgets the calibration
    (the planted fault: its columns dropped) misses by far more than the tolerance."""
    from brdf_infer.posterior import _targets

    model = build_posterior_model(
        (scene := _three_sample_scene(tmp_path)), scene.load_measurements()
    )
    sites = _draws_near_truth(model, 5, seed=1)
    mean, covariance = effect_moments(model, sites)[:2]
    for k in range(5):
        dense_mean, dense_cov = _dense_conditional(model, sites, k)
        assert_allclose(mean[k], dense_mean, rtol=0, atol=1e-10)
        assert_allclose(covariance[k], dense_cov, rtol=0, atol=1e-12)
    original = _targets._conditional_effects

    def without_calibration(residual, rest, diagonal, members, tau, scale):
        return original(residual, jnp.zeros_like(rest), diagonal, members, tau, scale)

    _targets._conditional_effects = without_calibration
    try:
        planted = effect_moments(model, sites)[0]
    finally:
        _targets._conditional_effects = original
    dense = np.array([_dense_conditional(model, sites, k)[0] for k in range(5)])
    assert np.max(np.abs(planted - dense)) > 1e3 * 1e-10


def test_the_sample_effects_are_zero_without_a_sample_effect(tmp_path):
    """``hierarchical = false``: every sample effect is 0 (measured = coating)."""
    scene = _three_sample_scene(tmp_path)
    text = (tmp_path / "scene.toml").read_text() + "hierarchical = false\n"
    (tmp_path / "scene.toml").write_text(text)
    scene = load_scene(tmp_path / "scene.toml")
    model = build_posterior_model(scene, scene.load_measurements())
    sites = _draws_near_truth(model, 3, seed=2)
    del sites["sample_sd"]
    mean, covariance = effect_moments(model, sites)[:2]
    assert not mean.any() and not covariance.any()


# ---------------------------------------------------------------- targets from effects


def test_each_target_scales_the_coating_by_its_own_factor():
    """coating: factor 1; new_part: e^u_new; measured: the samples' mean BRDF,
    ln mean_j e^u_j, or one sample's e^u_j by name; a sample is named for measured only."""
    effects = np.array([[0.1, -0.2], [0.0, 0.4]])
    new_part = np.array([0.3, -0.1])
    names = ("a", "b")
    assert not target_log_factor("coating", effects, new_part, names).any()
    assert_allclose(target_log_factor("new_part", effects, new_part, names), new_part)
    assert_allclose(
        target_log_factor("measured", effects, new_part, names),
        np.log(np.mean(np.exp(effects), axis=1)),
    )
    assert_allclose(target_log_factor("measured", effects, new_part, names, "b"), effects[:, 1])
    with pytest.raises(BadInputError, match="no sample 'c'"):
        target_log_factor("measured", effects, new_part, names, "c")
    with pytest.raises(BadInputError, match="measured target only"):
        target_log_factor("coating", effects, new_part, names, "a")


def test_auto_answers_the_measured_sample_for_one_sample_else_the_coating():
    assert chosen_target("auto", 1) == "measured"
    assert chosen_target("auto", 6) == "coating"
    assert chosen_target("new_part", 1) == "new_part"


def test_the_targets_record_holds_three_answers_and_per_sample_intervals():
    """Each target's TIS(70°) and π·BRDF0 are the coating's draws times its factor; several
    samples: the measured target also per sample; every target says its question."""
    rng = np.random.default_rng(0)
    headline = {"tis_70deg": np.full(4000, 0.05), "pi_brdf0": np.full(4000, 0.03)}
    effects = np.column_stack([np.full(4000, 0.2), np.full(4000, -0.1)])
    new_part = rng.normal(0.0, 0.1, 4000)
    record = targets_record(headline, effects, new_part, ("a", "b"), "coating", "learned")
    assert record["chosen"] == "coating" and record["tau_source"] == "learned"
    assert record["coating"]["tis_70deg"]["median"] == pytest.approx(0.05)
    mean_factor = np.mean(np.exp([0.2, -0.1]))
    assert record["measured"]["tis_70deg"]["median"] == pytest.approx(0.05 * mean_factor)
    assert record["measured"]["per_sample"]["a"]["pi_brdf0"]["median"] == pytest.approx(
        0.03 * np.exp(0.2)
    )
    low, high = np.exp(np.quantile(new_part, [0.025, 0.975]))
    assert record["new_part"]["tis_70deg"]["lo95"] == pytest.approx(0.05 * low)
    assert record["new_part"]["tis_70deg"]["hi95"] == pytest.approx(0.05 * high)
    assert {record[t]["question"] for t in QUESTIONS} == set(QUESTIONS.values())


# ---------------------------------------------------------------- τ from another run


def _fake_run(folder: Path, tau: np.ndarray) -> Path:
    """A run folder whose posterior.nc holds τ draws only (what a scene reads of it)."""
    import arviz

    folder.mkdir()
    arviz.from_dict(posterior={"sample_sd": tau.reshape(2, -1)}).to_netcdf(folder / "posterior.nc")
    return folder


@pytest.mark.full
def test_a_run_of_the_coating_gives_tau_its_prior(tmp_path):
    """``sample_sd_from`` reads the run's τ draws into a kernel density of ln τ, the prior the
    model samples: its quantiles are the run's (a skewed posterior stays skewed), and the
    learned record names the run; the run's folder is relative to the scene file."""
    from brdf_infer.posterior._likelihood import noise_prior

    rng = np.random.default_rng(0)
    tau = np.abs(rng.normal(0.03, 0.02, 4000)) + 1e-4  # half-normal-like: ln τ skewed left
    _fake_run(tmp_path / "coating_run", tau)
    scene = load_scene(series_ii_scene_file(tmp_path, 'sample_sd_from = "coating_run"'))
    prior = noise_prior(scene.errors, "sample_sd")
    for q in (0.05, 0.5, 0.95):
        assert float(prior.cdf(np.quantile(tau, q))) == pytest.approx(q, abs=0.02)
    draws = np.asarray(prior.sample(jax.random.PRNGKey(0), (4000,)))
    assert stats.ks_2samp(draws, tau).pvalue > 0.001
    assert "run coating_run's τ posterior" in scene.errors.sample_sd_prior_words()


@pytest.mark.parametrize(
    "errors, match",
    [
        ('sample_sd_from = "nowhere"', "errors.sample_sd_from': no posterior.nc here"),
        ("sample_sd = 0.03", "needs its source"),
        ('sample_sd = 0.03\nsample_sd_source = "x"\nsample_sd_from = "run"', "exclude each other"),
        ('sample_sd = "large"', 'expected "learned" or a number'),
        ('sample_sd_from = "few"', "positive draws of τ"),
    ],
)
def test_a_bad_tau_source_is_refused_naming_its_field(tmp_path, errors, match):
    _fake_run(tmp_path / "few", np.full(20, 0.03))
    with pytest.raises(BadInputError, match=match):
        load_scene(series_ii_scene_file(tmp_path, errors))


def test_a_stated_tau_is_data_of_the_model_not_a_site(tmp_path):
    """``sample_sd = 0.05`` with its source: no τ site; the draws' noise scales carry 0.05."""
    scene = load_scene(
        series_ii_scene_file(tmp_path, 'sample_sd = 0.05\nsample_sd_source = "six panels, 2025"')
    )
    assert not scene.errors.learns_sample_sd and scene.errors.stated_sample_sd == 0.05
    from brdf_infer.posterior._likelihood import drawn_noise_scales

    model = build_posterior_model(scene, scene.load_measurements())
    scales = drawn_noise_scales(scene.errors, model.data.noise, {"repeatability": np.ones(3)}, 3)
    assert_allclose(np.asarray(scales.sample_sd), np.full(3, 0.05))


# ---------------------------------------------------------------- end to end, one sample


@pytest.fixture(scope="module")
def one_sample_run(tmp_path_factory):
    """Series II of the bundled data as a one-sample scene, τ from a stand-in run of the
    coating (τ half-normal with scale 4.5 %, the shape of the bundled run's: median 3.0 %,
    95 % 0.14–10 %, ln τ skewed far to the left), sampled with the suite's reduced NUTS."""
    from brdf_infer.posterior import run_posterior
    from tests.helpers import REDUCED_NUTS

    folder = tmp_path_factory.mktemp("one")
    tau = np.abs(np.random.default_rng(0).normal(0.0, 0.045, 4000))
    _fake_run(folder / "coating_run", tau)
    scene = load_scene(series_ii_scene_file(folder, 'sample_sd_from = "coating_run"'))
    run = run_posterior(
        scene, scene.load_measurements(), out=folder / "run", seed=3, progress=False, **REDUCED_NUTS
    )
    return folder, run


@pytest.mark.slow
def test_a_one_sample_run_answers_for_the_measured_sample_with_tau_from_the_run(one_sample_run):
    """One sample: the bands are the measured sample's; new_part states the run τ came from
    and is wider than the measured; τ, which one sample cannot teach, keeps the run's
    posterior (its median within 4.5 Monte Carlo errors) and the sampler meets no trouble in
    its long left tail (every diagnostic passes; with kernels of Silverman's bandwidth alone,
    narrower than the gaps between its tail quantiles, series II with the bundled run's τ left
    33 divergent transitions and R-hat 1.53, 2026-11-29)."""
    _, run = one_sample_run
    summary = run.summary
    assert summary["diagnostics"]["failures"] == []
    tau = np.asarray(run.idata.posterior["sample_sd"])
    source = np.abs(np.random.default_rng(0).normal(0.0, 0.045, 4000))
    error = np.hypot(mcmc_quantile_se(tau, 0.5), quantile_se(source, 0.5, source.size))
    assert abs(np.median(tau) - np.median(source)) < MC_BOUND * error
    targets = summary["targets"]
    assert summary["target"] == targets["chosen"] == "measured"
    assert "coating_run" in targets["tau_source"]
    assert summary["tis_70deg"]["lo95"] == pytest.approx(targets["measured"]["tis_70deg"]["lo95"])
    width = {
        t: targets[t]["tis_70deg"]["hi95"] - targets[t]["tis_70deg"]["lo95"] for t in QUESTIONS
    }
    assert width["new_part"] > width["measured"]
    assert "answer is for the sample(s) measured" in summary["verdict"]["text"]
    assert "sample-to-sample effect carries" not in summary["verdict"]["text"]


@pytest.mark.slow
@pytest.mark.parametrize("target", ["measured", "coating", "new_part"])
def test_tis_of_a_run_follows_the_target_asked(one_sample_run, capsys, target):
    """``tis --run --target T --json`` at 70° is the summary's interval of T (one
    computation: the same draws and factors)."""
    folder, run = one_sample_run
    code, out, _ = run_cli(
        "tis",
        "--run",
        str(folder / "run"),
        "--theta-i",
        "70",
        "--target",
        target,
        "--json",
        capsys=capsys,
    )
    assert code == 0
    band = json.loads(out)
    assert band["target"] == target
    expected = run.summary["targets"][target]["tis_70deg"]
    assert band["lo95"][0] == pytest.approx(expected["lo95"], rel=1e-9)
    assert band["hi95"][0] == pytest.approx(expected["hi95"], rel=1e-9)


def test_a_target_or_sample_without_a_run_is_refused(capsys):
    code, _, err = run_cli("tis", "--target", "new_part", capsys=capsys)
    assert code == 2 and "--target" in err and "posterior run" in err
    code, _, err = run_cli(
        "tis", "--run", "x", "--target", "coating", "--sample", "a", capsys=capsys
    )
    assert code == 2 and "--sample" in err


# ---------------------------------------------------------------- a scatterometer table


TRUE_SAMPLE_EFFECT = 0.12  # the measured sample's own effect in the simulation [ln R]


@pytest.mark.slow
def test_a_hemisphere_table_of_one_sample_gives_the_measured_sample_its_own_width(tmp_path):
    """A scatterometer's table of one sample (3060 cells over the whole hemisphere at five
    incidence angles, 5 % noise per value, a 1 % calibration; simulated from Eqs. (7)–(8) at
    the UV parameters with the article's Δφ, the sample's own effect +0.12 in ln R; sampled by
    the default, Laplace + PSIS for a table): the measured TIS(70°) 95 %
    interval holds the sample's true TIS(70°), is no wider than the interval with the sample
    effect left out (within 4.5 Monte Carlo standard errors of the two widths), and lies within
    ± 5 % of its median: the calibration and the rows set it, not τ's prior; the verdict does
    not give the prior-set τ the measured sample's width."""
    from brdf_infer.model import tis
    from brdf_infer.posterior import load_run_target, run_posterior
    from brdf_infer.studies.synthetic import write_hemisphere_scene

    path = write_hemisphere_scene(
        tmp_path,
        UV_PAPER,
        dphi_scale=1.0,
        seed=5,
        sample_sd=0.0,
        errors="calibration_rel = 0.01",
        full=True,
    )
    rows = (tmp_path / "hemisphere.csv").read_text().splitlines()
    factor = np.exp(TRUE_SAMPLE_EFFECT)
    shifted = [rows[0]]
    for line in rows[1:]:
        *head, value, error = line.split(",")
        shifted.append(
            ",".join([*head, f"{float(value) * factor:.6e}", f"{float(error) * factor:.6e}"])
        )
    (tmp_path / "hemisphere.csv").write_text("\n".join(shifted) + "\n")
    scene = load_scene(path)
    run = run_posterior(
        scene, scene.load_measurements(), out=tmp_path / "run", seed=0, progress=False
    )
    summary = run.summary
    assert summary["target"] == "measured"
    truth = float(tis(70.0, UV_PAPER, False, scene.model.constants)) * factor
    measured = summary["targets"]["measured"]["tis_70deg"]
    assert measured["lo95"] < truth < measured["hi95"], (measured, truth)
    member, physical, _ = load_run_target(tmp_path / "run", "measured")
    values = np.exp(np.asarray(member.log_tis_draws(np.array([70.0]), physical)))[:, 0]
    ess = summary["diagnostics"]["ess_tail_min"]
    width_se = np.hypot(quantile_se(values, 0.025, ess), quantile_se(values, 0.975, ess))
    without = summary["width"]["tis_70deg"]["without"]["sample_effect"]
    without_se = np.hypot(without["mcse_lo95"], without["mcse_hi95"])
    width = measured["hi95"] - measured["lo95"]
    assert width <= without["hi95"] - without["lo95"] + MC_BOUND * np.hypot(width_se, without_se)
    assert (
        measured["hi95"] < 1.05 * measured["median"]
        and measured["lo95"] > 0.95 * measured["median"]
    )
    assert "sample-to-sample effect carries" not in summary["verdict"]["text"]


@pytest.mark.slow
def test_the_tis_quantile_export_of_a_new_part_is_its_flight_budget(one_sample_run, capsys):
    """``export --run --target new_part``: tis_q975 is the draw at the new part's 97.5 % TIS
    (a real BRDF), read back by the independent reader: its TIS(70°) is the new-part band's
    upper end (up to the gap between neighbouring draws), above the measured sample's; the
    file says which target it describes."""
    from tests import independent_bsdf as oracle

    folder, run = one_sample_run
    ends = {}
    for target in ("new_part", "measured"):
        out = folder / f"export-{target}"
        code, text, err = run_cli(
            "export", "--run", str(folder / "run"), "--theta-i", "70", "--azimuth-step", "15",
            "--radial-step", "5", "--target", target, "--out", str(out), "--json",
            capsys=capsys,
        )  # fmt: skip
        assert code == 0, err
        payload = json.loads(text)
        assert payload["target"] == target
        entry = {f["kind"]: f for f in payload["files"]}["tis_q975"]
        read = oracle.read_bsdf(entry["path"])
        assert any(f"target {target}" in line for line in read["comments"])
        ends[target] = float(read["tis"][0, 0])
        band = run.summary["targets"][target]["tis_70deg"]["hi95"]
        assert ends[target] == pytest.approx(band, rel=0.02)
    assert ends["new_part"] > ends["measured"]
