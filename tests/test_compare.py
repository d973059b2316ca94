"""``brdf-infer compare``: PSIS-LOO picks the family that made the data; the CLI contract."""

from __future__ import annotations

import dataclasses
import itertools
import json
import warnings
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from brdf_infer.cli.compare import comparison_table
from brdf_infer.model import family
from brdf_infer.model.error_model import NoiseScales
from brdf_infer.model.params import UV_PAPER
from brdf_infer.posterior import build_posterior_model
from brdf_infer.report._compare import compare_frame, label
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


@pytest.mark.full
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


@pytest.mark.full
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


@pytest.mark.full
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


def _hand_made_fit(name: str, log_lik: np.ndarray, centres: np.ndarray, **refits):
    from brdf_infer._internal import arviz as az
    from brdf_infer.studies.compare import FamilyResult

    idata = az.from_dict(posterior={"mu": centres}, log_likelihood={"obs": log_lik})
    refits = {"refitted_rows": [], "exact_elpd": {}, **refits}
    return FamilyResult(name, {}, {}, idata, 1.0, 400.0, 0, **refits, seconds=0)


def test_the_ranking_is_arviz_loo_and_compare_of_the_same_terms():
    """The ranking's PSIS-LOO is the run's (posterior.psis_loo with the relative efficiency of
    the family's draws), its differences, their standard errors and its stacking weights the
    comparison's own: ArviZ's ``loo`` and ``compare(method="stacking")`` of the same pointwise
    terms, the independent reference, give the same numbers (1e-9; the weights, an
    optimiser's, 1e-6). Three hand-made families on 30 rows, autocorrelated chains (a relative
    efficiency below 1) and a heavy row."""
    from brdf_infer._internal import arviz as az
    from brdf_infer.studies.compare import rank_families

    rng = np.random.default_rng(4)
    y = rng.normal(size=30)
    y[7] = 5.0
    fits, idatas = {}, {}
    for index, (name, spread) in enumerate([("a", 0.3), ("b", 0.6), ("c", 1.2)]):
        walk = np.cumsum(rng.normal(size=(4, 250)), axis=1) * 0.02 + 0.1 * index
        centres = walk + rng.normal(0.0, 0.2, size=walk.shape)
        log_lik = -0.5 * ((y - centres[..., None]) / spread) ** 2 - np.log(spread)
        fits[name] = _hand_made_fit(name, log_lik, centres)
        idatas[name] = fits[name].idata
    table, _ = rank_families(fits)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        expected = az.compare(
            {name: az.loo(idata, pointwise=True) for name, idata in idatas.items()},
            ic="loo",
            method="stacking",
        )
    assert [row["name"] for row in table] == list(expected.index)
    for row in table:
        reference = expected.loc[row["name"]]
        for key, theirs in [
            ("elpd_loo", "elpd_loo"),
            ("se", "se"),
            ("p_loo", "p_loo"),
            ("d_elpd", "elpd_diff"),
            ("dse", "dse"),
        ]:
            assert row[key] == pytest.approx(float(reference[theirs]), rel=1e-9, abs=1e-9), key
        assert row["weight"] == pytest.approx(float(reference["weight"]), abs=1e-6)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            k = np.asarray(az.loo(idatas[row["name"]], pointwise=True).pareto_k)
        assert row["pareto_k_max"] == pytest.approx(float(np.max(k)), abs=1e-12)
    assert table[1]["dse"] > 0 and sum(row["weight"] for row in table) == pytest.approx(1.0)
    assert 0.0 < max(row["weight"] for row in table) < 1.0  # the stacking is not trivial
    assert max(row["pareto_k_max"] for row in table) > 0.7  # the heavy row is seen


@pytest.mark.slow  # ≈ 10 s of sampling and one refit, but its own compile (30-60 s on 2 cores):
# the single-series structure is compiled by no other test of the default suite
def test_a_row_with_pareto_k_above_0_7_is_refitted_on_a_single_series_scene(tmp_path):
    """A user scene of one series, θi 10-70° (synthetic.GEOMETRIES "single-series", data
    seed 3), its row 0 (θi = 10°, θs = 0°) planted 4 times too bright: with 2 × 300 draws its
    Pareto k lies far above the limit of 600 draws (1 − 1/log₁₀ 600 = 0.64; unplanted it had
    k ≈ 0.8 ± 0.12 from run to run, too near the limit for a test that must cross it on
    every CPU), so its LOO term is computed by refitting without it, as is every row above
    that limit whose refit passes the run's checks; elpd_loo and p_loo of the ranking carry
    the exact terms."""
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
    # every such row is refitted unless its refit fails the run's checks (divergences,
    # R-hat > 1.01 over 2 × 300 draws), which leaves its PSIS term; the planted row is
    assert 0 in fit.refitted_rows and set(fit.refitted_rows) <= set(high)
    assert set(fit.exact_elpd) == set(fit.refitted_rows)
    assert all(np.isfinite(value) for value in fit.exact_elpd.values())
    table, notes = rank_families({"strumik2024": fit, "psis only": _psis_only(fit)})
    rows, shift = _with_refit_effect(fit, table)
    assert shift != 0.0
    refitted, psis = rows["strumik2024"], rows["psis only"]
    assert refitted["elpd_loo"] == pytest.approx(psis["elpd_loo"] + shift, rel=1e-12)
    assert refitted["p_loo"] == pytest.approx(psis["p_loo"] - shift, rel=1e-12)
    assert refitted["pareto_k_limit"] == pytest.approx(limit)
    left = [row for row in high if row not in fit.refitted_rows]  # refits refused
    after = max([float(k[row]) for row in left], default=0.0)
    assert refitted["pareto_k_max"] > limit
    assert refitted["pareto_k_max_after_refit"] <= max(after, limit)
    assert any(f"rows {fit.refitted_rows}" in note and "LOO by refit" in note for note in notes), (
        notes
    )


@pytest.mark.full
def test_fit_lsq_of_another_family_gives_its_parameters_in_json(capsys):
    code, out, err = run_cli("fit", "--method", "lsq", "--model", "abg", "--json", capsys=capsys)
    assert code == 0, err
    payload = json.loads(out)
    assert set(payload["params"]) == {"A", "B", "g"} and payload["model"] == "abg"
    assert all(np.isfinite(v) and v > 0 for v in payload["params"].values())
    assert payload["n_points"] == 42
    # every family is weighted alike: the learned repeatability makes χ² = n − p = 39
    # (Paule–Mandel), the dof count it too (38), and ABg, with one value at specular for every
    # θi while the data grow 100-fold there, needs a σ_rep no data of the scene's error model
    # give (prior predictive p < 0.001); no χ²/dof sentence where σ_rep is learned
    assert payload["dof"] == 38 and payload["cost"] == pytest.approx(39.0, abs=1e-6)
    assert payload["repeatability"] > 1.0 and payload["poor_fit"]
    assert payload["repeatability_p_value"] < 1e-3
    assert payload["fit_quality"].startswith("poor: the learned repeatability")
    assert "χ²/dof" not in payload["fit_quality"]
    assert "more than the scene's error model gives its data" in payload["fit_quality"]
    assert np.array(payload["correlation"]).shape == (3, 3)
    assert payload["correlation_names"] == ["A", "B", "g"] and "paper_fit_cost" not in payload
    assert payload["sigma_scaled"] == pytest.approx(payload["sigma"], rel=1e-6)


@pytest.mark.full
def test_fit_lsq_of_another_family_states_its_quality_beside_its_table(capsys):
    code, out, err = run_cli("fit", "--method", "lsq", "--model", "abg", capsys=capsys)
    assert code == 0, err
    assert "least-squares fit of abg to scene 'lya'" in out and "1 sigma x sqrt(chi2/dof)" in out
    assert "fit quality: poor: the learned repeatability" in out and "correlation:" in out


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


@pytest.mark.full
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


def stub_comparison(bands: dict[str, tuple[float, float, float]], failing=()) -> dict:
    """A ``compare`` JSON payload of the families ``bands`` (TIS(70°) median, lo95, hi95 as
    fractions, best first); the families in ``failing`` with failed sampler diagnostics."""
    models = []
    for rank, (name, (median, lo95, hi95)) in enumerate(bands.items()):
        ok = name not in failing
        models.append(
            {
                "name": name,
                "elpd_loo": 30.0 - 20.0 * rank,
                "se": 5.0,
                "d_elpd": 20.0 * rank,
                "dse": 6.0 if rank else 0.0,
                "weight": 0.0 if rank else 1.0,
                "p_loo": 6.0,
                "pareto_k_max": 0.4,
                "pareto_k_max_after_refit": 0.4,
                "tis70": {"median": median, "lo95": lo95, "hi95": hi95},
                "r_hat_max": 1.002 if ok else 1.04,
                "ess_bulk_min": 1800.0 if ok else 124.0,
                "divergences": 0,
                "sampler_ok": ok,
                "sampler_failures": [] if ok else ["R-hat 1.040 > 1.01"],
            }
        )
    return {"models": models, "warnings": [], "seconds": 1.0}


# TIS(70°) bands within one decade (the families of a glossy fit) and over two (the bundled
# data's: Lambertian 56 %, ABg 0.94 %, docs/families.md), and two families within 1 %
NARROW = {
    "strumik2024": (0.058, 0.052, 0.065),
    "abg": (0.055, 0.049, 0.061),
    "harvey-shack": (0.061, 0.050, 0.073),
    "lambertian": (0.039, 0.037, 0.041),
    "lambertian+abg": (0.059, 0.051, 0.068),
}
BUNDLED = {
    "strumik2024": (0.0654, 0.0584, 0.0735),
    "harvey-shack": (0.0083, 0.0035, 0.0472),
    "abg": (0.0094, 0.0038, 0.0486),
    "lambertian+abg": (0.0181, 0.0057, 0.162),
    "lambertian": (0.56, 0.39, 0.76),
}
CLOSE = {"strumik2024": (0.0572, 0.0561, 0.0583), "abg": (0.0569, 0.0560, 0.0578)}


def test_compare_prints_tis_in_percent_and_its_json_keeps_fractions(capsys, monkeypatch):
    """The human table gives TIS(70°) in percent (its unit in the header), 100 times the
    JSON's fractions; the study itself is stubbed (its sampling is tested above)."""
    payload = stub_comparison(BUNDLED)
    result = SimpleNamespace(as_json=lambda: payload, warnings=[], seconds=1.0)
    monkeypatch.setattr("brdf_infer.studies.compare.compare_families", lambda *a, **k: result)
    argv = ["compare", "lya", "--models", *BUNDLED]
    code, out, err = run_cli(*argv, "--json", capsys=capsys)
    assert code == 0, err
    fractions = {m["name"]: m["tis70"] for m in json.loads(out)["models"]}
    assert fractions["lambertian"] == {"median": 0.56, "lo95": 0.39, "hi95": 0.76}
    code, out, err = run_cli(*argv, capsys=capsys)
    assert code == 0, err
    header, _, *rows = out.splitlines()[1:]
    assert "TIS(70°) [%] (95 %)" in header
    for name, band in fractions.items():
        (row,) = [row for row in rows if row.split()[0] == name]
        median, lo95, hi95 = (100 * band[key] for key in ("median", "lo95", "hi95"))
        assert row.rstrip().endswith(f"{median:.2f} ({lo95:.2f}–{hi95:.2f})"), row


def text_boxes(figure):
    """Every drawn, non-empty text of ``figure`` (tick labels within their axis' view, axis
    labels, titles) as (axes, kind, text, window extent) after drawing it with Agg."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(figure)
    canvas.draw()
    renderer = canvas.get_renderer()
    found = []
    for number, axes in enumerate(figure.axes):
        low, high = sorted(axes.get_xlim())
        for minor in (False, True):
            for tick in axes.xaxis.get_ticklabels(minor=minor):
                inside = low * (1 - 1e-9) <= tick.get_position()[0] <= high * (1 + 1e-9)
                if tick.get_visible() and tick.get_text() and inside:
                    found.append(
                        (number, "xtick", tick.get_text(), tick.get_window_extent(renderer))
                    )
        for kind, text in (("xlabel", axes.xaxis.label), ("ylabel", axes.yaxis.label)):
            if text.get_visible() and text.get_text():
                found.append((number, kind, text.get_text(), text.get_window_extent(renderer)))
        for tick in axes.yaxis.get_ticklabels():
            if tick.get_visible() and tick.get_text():
                found.append((number, "ytick", tick.get_text(), tick.get_window_extent(renderer)))
    return found, figure.bbox


@pytest.mark.parametrize("bands", [NARROW, BUNDLED, CLOSE], ids=["narrow", "bundled", "close"])
def test_compare_figure_labels_neither_overlap_nor_leave_the_figure(bands):
    """compare.png's tick labels of each x axis stand apart, every label lies inside the
    figure, and each x axis names its unit. (Planted: the old log axis with its default
    labels overran "4×10⁰ 5×10⁰ …" on the narrow bands, and its layout cut the TIS label.)"""
    from brdf_infer.report._compare import compare_plot

    figure = compare_plot(stub_comparison(bands, failing=("harvey-shack",)))
    boxes, frame = text_boxes(figure)
    for number in {number for number, *_ in boxes}:
        ticks = sorted(
            (box for n, kind, _, box in boxes if n == number and kind == "xtick"),
            key=lambda box: box.x0,
        )
        assert len(ticks) >= 2, (number, ticks)
        for before, after in itertools.pairwise(ticks):
            assert before.x1 < after.x0, (number, [t for n, k, t, _ in boxes if k == "xtick"])
    for _, kind, text, box in boxes:
        assert frame.x0 <= box.x0 and box.x1 <= frame.x1, (kind, text, box)
        assert frame.y0 <= box.y0 and box.y1 <= frame.y1, (kind, text, box)
    xlabels = [text for _, kind, text, _ in boxes if kind == "xlabel"]
    assert len(xlabels) == 2 and "[nats]" in xlabels[0] and "[%]" in xlabels[1], xlabels
    # the TIS panel names no family: each point stands level with its family's compare row
    left, right = figure.axes
    rows = dict(zip([t.get_text() for t in left.get_yticklabels()], left.get_yticks(), strict=True))
    points = {
        (float(x), float(y))
        for bar in right.containers
        for x, y in zip(*bar.lines[0].get_data(), strict=True)
    }
    assert points == {
        (100 * entry["tis70"]["median"], rows[label(entry)])
        for entry in stub_comparison(bands, failing=("harvey-shack",))["models"]
    }
