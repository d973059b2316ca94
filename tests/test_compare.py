"""``brdf-infer compare``: PSIS-LOO picks the family that made the data; the CLI contract."""

from __future__ import annotations

import dataclasses
import json
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from brdf_infer.cli.compare import comparison_table
from brdf_infer.model import family
from brdf_infer.model.error_model import NoiseScales
from brdf_infer.model.params import UV_PAPER
from brdf_infer.posterior import build_posterior_model
from brdf_infer.report._compare import compare_frame
from brdf_infer.studies.compare import PARETO_K_LIMIT, CompareSettings, compare_families
from brdf_infer.verdict import pareto_k_limit
from tests.helpers import SUITE_WARMUP, run_cli

# the posterior's target acceptance (compare's default is 0.9) and the suite's warmup: the
# families' NUTS programs are those of the suite's posterior runs, compiled once
SMALL = CompareSettings(chains=2, warmup=SUITE_WARMUP, draws=300, seed=1, target_accept=0.8)
ABG_TRUTH = {"A": 2.0e-3, "B": 5.0e-3, "g": 1.8}


def synthetic(scene, measurements, truth: str, seed: int):
    """The bundled geometry with ln R drawn from ``truth`` under the scene's error model
    (sample and repeatability scales 0.05)."""
    if truth == "abg":
        model = build_posterior_model(scene, measurements, family("abg"))
        params = {k: jnp.asarray(v) for k, v in ABG_TRUTH.items()}
    else:
        model = build_posterior_model(scene, measurements)
        params = UV_PAPER._asdict()
    errors = scene.errors
    scales = NoiseScales(
        sample_sd=jnp.asarray(0.05),
        repeatability=jnp.asarray(0.05),
        calibration=jnp.asarray(errors.calibration_sd),
        rotation_deg=jnp.asarray(errors.rotation_deg if errors.angles_on else 0.0),
        camera_deg=jnp.asarray(errors.camera_deg if errors.angles_on else 0.0),
    )
    parts = model.likelihood_parts(params, scales)
    first, second = jax.random.split(jax.random.PRNGKey(seed))
    draw = (
        parts.mean
        + parts.factor @ jax.random.normal(first, (parts.factor.shape[1],))
        + jnp.sqrt(parts.diagonal) * jax.random.normal(second, parts.mean.shape)
    )
    reflectance = np.exp(np.asarray(draw))
    ratio = reflectance / measurements.reflectance
    errors_column = (
        None if measurements.reflectance_err is None else measurements.reflectance_err * ratio
    )
    return dataclasses.replace(measurements, reflectance=reflectance, reflectance_err=errors_column)


@pytest.mark.parametrize("truth", [pytest.param("abg", marks=pytest.mark.slow), "strumik2024"])
def test_compare_ranks_the_family_that_generated_the_data_first(lya, truth):
    scene, measurements = lya
    data = synthetic(scene, measurements, truth, seed=4)
    result = compare_families(scene, data, ["strumik2024", "abg"], SMALL)
    best, other = result.table
    assert best["name"] == truth, result.table
    assert best["d_elpd"] == 0.0 and other["d_elpd"] > 3.0 * other["dse"], result.table
    if truth == "abg":
        parameters = result.families["abg"].parameters
        for name, value in ABG_TRUTH.items():
            assert parameters[name]["lo95"] <= value <= parameters[name]["hi95"], name


def assert_png_shows_the_comparison(path, models: int) -> None:
    """compare.png is ArviZ's compare plot (left, 3/5 of the width) beside the TIS panel: a PNG
    of 10 in × (0.6 per model + 1.8) in at 90 dpi, each panel with drawn (non-white) pixels
    and more than two colours. A blank figure, a panel left empty or a figure not sized by the
    number of models fails (planted by hand: all three fail, an axes-with-a-line figure passes)."""
    from matplotlib.image import imread

    image = imread(path)
    assert image.shape[:2] == (round(90 * (0.6 * models + 1.8)), 900), image.shape
    drawn = np.any(image[..., :3] < 0.9, axis=-1)
    for panel in (drawn[:, :500], drawn[:, 560:]):
        assert panel.mean() > 0.01, panel.mean()
    assert len(np.unique(image[..., :3].reshape(-1, 3), axis=0)) > 2


def test_compare_command_json_contract_and_files(tmp_path, capsys):
    """At the settings of ``SMALL`` the two families' NUTS programs are the suite's (the lya
    posterior's and the ABg run's): one chain of 100 draws costs no compilation of its own.
    ``--no-refit``: at 100 draws four rows have Pareto k > 0.7, and each exact refit is another
    NUTS run, warmup included; the refits' arithmetic is checked by
    test_refitted_terms_replace_psis_in_elpd_and_p_loo, a refitting comparison by the slow
    test_a_row_with_pareto_k_above_0_7_is_refitted_on_a_single_series_scene."""
    code, out, err = run_cli(
        "compare",
        "lya",
        "--models",
        "strumik2024",
        "abg",
        "--chains",
        "1",
        "--warmup",
        str(SMALL.warmup),
        "--target-accept",
        str(SMALL.target_accept),
        "--draws",
        "100",
        "--no-refit",
        "--out",
        str(tmp_path / "cmp"),
        "--json",
        capsys=capsys,
    )
    assert code == 0, err
    payload = json.loads(out)
    assert sorted(m["name"] for m in payload["models"]) == ["abg", "strumik2024"]
    for entry in payload["models"]:
        for key in ("elpd_loo", "se", "d_elpd", "dse", "weight", "p_loo", "pareto_k_max"):
            assert np.isfinite(entry[key]), key
        assert entry["tis70"]["lo95"] <= entry["tis70"]["median"] <= entry["tis70"]["hi95"]
    assert payload["models"][0]["d_elpd"] == 0.0
    assert sum(m["weight"] for m in payload["models"]) == pytest.approx(1.0)
    written = json.loads((tmp_path / "cmp" / "compare.json").read_text())
    for key in ("name", "elpd_loo", "d_elpd", "dse", "weight"):  # the file is what was printed
        assert [m[key] for m in written["models"]] == [m[key] for m in payload["models"]], key
    assert_png_shows_the_comparison(tmp_path / "cmp" / "compare.png", len(payload["models"]))
    # one chain of 100 draws cannot reach a bulk ESS of 400 (and has no R-hat: NaN, which
    # fails as in a posterior run): every family's sampler diagnostics fail, stand next to
    # its rank, and mark it not to be trusted
    for entry in payload["models"]:
        assert np.isnan(entry["r_hat_max"]) and entry["ess_bulk_min"] < 400
        assert isinstance(entry["divergences"], int)
        assert entry["sampler_ok"] is False
        assert any(f.startswith("bulk ESS") for f in entry["sampler_failures"]), entry
    assert any("not to be trusted" in note for note in payload["warnings"])
    text = comparison_table(payload)
    assert "R-hat max" in text and "ESS bulk min" in text and "FAIL" in text
    assert text.count("its place in the ranking is not to be trusted") == 2
    assert all("(sampler diagnostics fail)" in name for name in compare_frame(payload).index)


@pytest.mark.parametrize(
    ("models", "message"),
    [(["strumik2024", "phong"], "unknown model family 'phong'"), (["abg"], "at least two")],
)
def test_compare_refuses_bad_model_lists_before_any_work(tmp_path, capsys, models, message):
    code, out, err = run_cli(
        "compare", "--models", *models, "--out", str(tmp_path / "x"), capsys=capsys
    )
    assert code == 2 and out == "" and message in err and "--models" in err
    assert "Traceback" not in err and not (tmp_path / "x").exists()


@pytest.mark.parametrize(
    ("value", "message"),
    [('["strumik2024", "phong"]', "unknown model family 'phong'"), ('["abg"]', "at least two")],
)
def test_scene_compare_key_is_checked_when_the_scene_loads(lya, tmp_path, value, message):
    from brdf_infer.errors import BadInputError
    from brdf_infer.scene import load_scene

    scene, _ = lya
    path = tmp_path / "scene.toml"
    path.write_text(
        f'name = "x"\nmeasurements = "{scene.measurements_path.as_posix()}"\n'
        f"compare = {value}\n"
        "[series.I]\naperture_diameter_mm = 7.2\naperture_distance_mm = 103.8\n"
        "[series.II]\naperture_diameter_mm = 7.5\naperture_distance_mm = 106.0\n"
    )
    with pytest.raises(BadInputError, match=message) as error:
        load_scene(path)
    assert error.value.field == "compare"


def test_scene_lists_the_families_run_compares(lya, tmp_path):
    from brdf_infer.scene import load_scene

    scene, _ = lya
    path = tmp_path / "scene.toml"
    path.write_text(
        f'name = "x"\nmeasurements = "{scene.measurements_path.as_posix()}"\n'
        'compare = ["strumik2024", "abg", "abg"]\n'
        "[series.I]\naperture_diameter_mm = 7.2\naperture_distance_mm = 103.8\n"
        "[series.II]\naperture_diameter_mm = 7.5\naperture_distance_mm = 106.0\n"
    )
    assert load_scene(path).studies.compare == ("strumik2024", "abg")
    path.write_text(path.read_text().replace("compare = ", "[studies]\ncompare = ", 1))
    assert load_scene(path).studies.compare == ("strumik2024", "abg")


def test_a_row_with_the_left_out_sigma_carries_no_information(lya):
    """The exact-refit device: with σ = LEFT_OUT_SIGMA on row i the likelihood of all rows
    differs from that of the other rows alone by a constant in the parameters, so the refit
    posterior is the posterior without row i."""
    import numpyro.distributions as dist

    from brdf_infer.posterior import LEFT_OUT_SIGMA

    scene, measurements = lya
    model = build_posterior_model(scene, measurements, family("abg"))
    row = 7
    noise = model.data.noise
    left_out = model.data._replace(
        noise=noise._replace(sigma_row=noise.sigma_row.at[row].set(LEFT_OUT_SIGMA))
    )
    y = model.data.rows.log_reflectance
    keep = np.arange(y.shape[0]) != row
    differences = []
    calibration = scene.errors.calibration_sd  # the per-series effect row 7 shares with others
    assert calibration > 0
    for a, b, g, sd in ((2e-3, 5e-3, 1.8, 0.05), (1e-2, 1e-1, 2.5, 0.2), (5e-4, 1e-3, 1.2, 0.01)):
        params = {"A": jnp.asarray(a), "B": jnp.asarray(b), "g": jnp.asarray(g)}
        scales = NoiseScales(*(jnp.asarray(v) for v in (sd, 0.05, calibration, 0.3, 0.3)))
        full = model.likelihood_parts(params, scales, left_out)
        dropped = model.likelihood_parts(params, scales)
        whole = dist.LowRankMultivariateNormal(full.mean, full.factor, full.diagonal).log_prob(y)
        rest = dist.LowRankMultivariateNormal(
            dropped.mean[keep], dropped.factor[keep], dropped.diagonal[keep]
        ).log_prob(y[keep])
        differences.append(float(whole - rest))
    assert np.ptp(differences) < 1e-6, differences


def _psis_only(fit):
    """The same posterior ranked without its refits (the PSIS terms kept everywhere)."""
    return dataclasses.replace(fit, refitted_rows=[], exact_elpd={})


def _with_refit_effect(fit, table):
    """The rows of a ranking ``table`` by name, and the exact minus the PSIS terms of the
    refitted rows of ``fit``."""
    from brdf_infer._internal import arviz as az

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        psis = np.asarray(az.loo(fit.idata, pointwise=True).loo_i)
    shift = sum(value - psis[row] for row, value in fit.exact_elpd.items())
    rows = {row["name"]: row for row in table}
    return rows, shift


def test_refitted_terms_replace_psis_in_elpd_and_p_loo():
    """Bookkeeping of the exact refit, on a hand-made posterior (no sampling): the ranked
    elpd_loo is the PSIS sum with the refitted rows' exact terms put in, and p_loo = lppd −
    elpd_loo (ArviZ's definition, lppd = Σᵢ ln mean_s exp(log_lik)) moves by the opposite
    amount; Pareto k of a refitted row counts as 0 afterwards."""
    from brdf_infer._internal import arviz as az
    from brdf_infer.studies.compare import FamilyResult, rank_families

    rng = np.random.default_rng(0)
    y = rng.normal(size=12)
    y[3] = 6.0  # an outlier: its PSIS weights have a heavy tail
    centres = rng.normal(0.0, 0.3, size=(2, 200, 1))
    log_lik = -0.5 * (y - centres) ** 2 - 0.5 * np.log(2 * np.pi)
    idata = az.from_dict(posterior={"mu": centres[..., 0]}, log_likelihood={"obs": log_lik})
    fit = FamilyResult(
        "model", {}, {}, idata, 1.0, 400.0, 0, refitted_rows=[3], exact_elpd={3: -25.0}, seconds=0
    )
    table, notes = rank_families({"model": fit, "psis only": _psis_only(fit)})
    rows, shift = _with_refit_effect(fit, table)
    flat = log_lik.reshape(-1, y.size)
    lppd = np.sum(np.log(np.mean(np.exp(flat), axis=0)))
    assert rows["model"]["elpd_loo"] == pytest.approx(rows["psis only"]["elpd_loo"] + shift)
    assert rows["model"]["p_loo"] == pytest.approx(lppd - rows["model"]["elpd_loo"], rel=1e-10)
    assert rows["psis only"]["p_loo"] == pytest.approx(lppd - rows["psis only"]["elpd_loo"])
    assert (
        rows["model"]["pareto_k_max"] > PARETO_K_LIMIT >= rows["model"]["pareto_k_max_after_refit"]
    )
    assert any("LOO by refit" in note for note in notes)


@pytest.mark.slow  # ≈ 10 s of sampling and one refit, but its own compile (30-60 s on 2 cores):
# the single-series structure is compiled by no other test of the default suite
def test_a_row_with_pareto_k_above_0_7_is_refitted_on_a_single_series_scene(tmp_path):
    """A user scene of one series, θi 10-70° (synthetic.GEOMETRIES "single-series", data
    seed 3), its row 0 (θi = 10°, θs = 0°) planted 4 times too bright: with 2 × 300 draws its
    Pareto k lies far above the limit of 600 draws (1 − 1/log₁₀ 600 = 0.64; unplanted it had
    k ≈ 0.8 ± 0.12 from run to run, too near the limit for a test that must cross it on
    every CPU), so its LOO term is computed by refitting without it, as is every row above
    that limit; elpd_loo and p_loo of the ranking carry the exact terms."""
    from brdf_infer._internal import arviz as az
    from brdf_infer.scene import load_scene
    from brdf_infer.studies.compare import fit_family, rank_families
    from brdf_infer.studies.synthetic import write_geometry_scene

    scene = load_scene(write_geometry_scene(tmp_path, "single-series", UV_PAPER, seed=3))
    rows = scene.load_measurements()
    rows = dataclasses.replace(
        rows, reflectance=rows.reflectance * np.r_[4.0, np.ones(len(rows) - 1)]
    )
    fit = fit_family(scene, rows, "strumik2024", SMALL)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # ArviZ warns about the very row this test is about
        k = np.asarray(az.loo(fit.idata, pointwise=True).pareto_k)
    sizes = fit.idata.posterior.sizes
    limit = pareto_k_limit(sizes["chain"] * sizes["draw"])
    high = [int(row) for row in np.flatnonzero(k > limit)]
    assert high, k  # the scene has such a row
    assert fit.refitted_rows == high and set(fit.exact_elpd) == set(high)
    assert all(np.isfinite(value) for value in fit.exact_elpd.values())
    table, notes = rank_families({"strumik2024": fit, "psis only": _psis_only(fit)})
    rows, shift = _with_refit_effect(fit, table)
    assert shift != 0.0
    refitted, psis = rows["strumik2024"], rows["psis only"]
    assert refitted["elpd_loo"] == pytest.approx(psis["elpd_loo"] + shift, rel=1e-12)
    assert refitted["p_loo"] == pytest.approx(psis["p_loo"] - shift, rel=1e-12)
    assert refitted["pareto_k_limit"] == pytest.approx(limit)
    assert refitted["pareto_k_max"] > limit >= refitted["pareto_k_max_after_refit"]
    assert any(f"rows {high}" in note and "LOO by refit" in note for note in notes), notes


def test_fit_lsq_of_another_family_gives_its_parameters_in_json(capsys):
    code, out, err = run_cli("fit", "--method", "lsq", "--model", "abg", "--json", capsys=capsys)
    assert code == 0, err
    payload = json.loads(out)
    assert set(payload["params"]) == {"A", "B", "g"} and payload["model"] == "abg"
    assert all(np.isfinite(v) and v > 0 for v in payload["params"].values())
    assert payload["n_points"] == 42
    # every family is weighted alike: the learned repeatability makes χ²/dof 1 (Paule–Mandel),
    # and ABg, with one value at specular for every θi while the data grow 100-fold there,
    # needs a σ_rep no data of the scene's error model give (prior predictive p < 0.001)
    assert payload["dof"] == 39 and payload["chi2_dof"] == pytest.approx(1.0, abs=1e-6)
    assert payload["repeatability"] > 1.0 and payload["poor_fit"]
    assert payload["repeatability_p_value"] < 1e-3
    assert payload["fit_quality"].startswith("poor: χ²/dof = 1 for 39 dof")
    assert "more than the scene's error model gives its data" in payload["fit_quality"]
    assert np.array(payload["correlation"]).shape == (3, 3)
    assert payload["correlation_names"] == ["A", "B", "g"] and "paper_fit_cost" not in payload
    assert payload["sigma_scaled"] == pytest.approx(payload["sigma"], rel=1e-6)


def test_fit_lsq_of_another_family_states_its_quality_beside_its_table(capsys):
    code, out, err = run_cli("fit", "--method", "lsq", "--model", "abg", capsys=capsys)
    assert code == 0, err
    assert "least-squares fit of abg to scene 'lya'" in out and "1 sigma x sqrt(chi2/dof)" in out
    assert "fit quality: poor: χ²/dof = 1 for 39 dof" in out and "correlation:" in out


@pytest.mark.parametrize(
    ("argv", "message"),
    [(["--model", "phong"], "unknown model family"), (["--model", "abg"], "--method lsq")],
)
def test_fit_refuses_unknown_families_and_the_paper_method_for_others(capsys, argv, message):
    code, out, err = run_cli("fit", *argv, capsys=capsys)
    assert code == 2 and out == "" and message in err and "--model" in err


def _family_scene(lya, tmp_path, family_name: str):
    scene, _ = lya
    path = tmp_path / "scene.toml"
    path.write_text(
        f'name = "x"\nmeasurements = "{scene.measurements_path.as_posix()}"\n'
        "[series.I]\naperture_diameter_mm = 7.2\naperture_distance_mm = 103.8\n"
        "[series.II]\naperture_diameter_mm = 7.5\naperture_distance_mm = 106.0\n"
        f'[model]\nfamily = "{family_name}"\n'
    )
    return path


def test_scene_model_family_is_what_fit_uses(lya, tmp_path, capsys):
    path = _family_scene(lya, tmp_path, "lambertian")
    code, out, err = run_cli("fit", str(path), "--method", "lsq", "--json", capsys=capsys)
    assert code == 0, err
    assert json.loads(out)["model"] == "lambertian"


def test_unknown_scene_model_family_is_named(lya, tmp_path):
    from brdf_infer.errors import BadInputError
    from brdf_infer.scene import load_scene

    with pytest.raises(BadInputError, match="unknown model family 'phong'") as error:
        load_scene(_family_scene(lya, tmp_path, "phong"))
    assert error.value.field == "model.family"
