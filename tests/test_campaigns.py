"""Pooled campaigns (``[campaigns.NAME]``, :mod:`brdf_infer.scene._campaigns`): several
measurement files of one coating in one posterior, each with its own series, samples and data
options of the error model, sharing the coating's parameters and τ; each calibration factor
learned, each campaign's rows checked and scored (:mod:`brdf_infer.posterior._campaigns`)."""

from __future__ import annotations

import json
from pathlib import Path

import arviz as az
import numpy as np
import pytest

from brdf_infer.errors import BadInputError
from brdf_infer.model.error_model import calibration_group_names, noise_layout
from brdf_infer.model.params import UV_PAPER, params_to_dict
from brdf_infer.posterior import build_posterior_model
from brdf_infer.scene import load_scene
from brdf_infer.studies.synthetic import synthetic_measurements
from tests.helpers import MC_BOUND, assert_allclose, mcmc_quantile_se, run_cli

LYA_SERIES = {"I": (7.2, 103.8), "II": (7.5, 110.0)}
HEADER = "series,sample,theta_i_deg,theta_s_deg,reflectance,reflectance_err"


def _write_rows(path: Path, rows, series: str, sample_names) -> None:
    lines = [HEADER]
    for k in range(len(rows)):
        lines.append(
            f"{series},{sample_names[k]},{rows.theta_i_deg[k]:g},{rows.theta_s_deg[k]:g},"
            f"{rows.reflectance[k]:.9e},{rows.reflectance_err[k]:.9e}"
        )
    path.write_text("\n".join(lines) + "\n")


def _campaign_table(name: str, file: str, series: str, errors: str = "") -> str:
    diameter, distance = LYA_SERIES[series]
    text = (
        f'[campaigns.{name}]\nmeasurements = "{file}"\n[campaigns.{name}.series.{series}]\n'
        f"aperture_diameter_mm = {diameter}\naperture_distance_mm = {distance}\n"
    )
    return text + (f"[campaigns.{name}.errors]\n{errors}\n" if errors else "")


def _lya_split(folder: Path, off_errors: str = "", shared: str = "") -> Path:
    """The bundled rows as two campaigns, series I (``specular``, 12 images a row) and series
    II (``off``, with ``off_errors``), ``shared`` the scene's [errors] lines."""
    lya = load_scene("lya")
    rows = lya.load_measurements()
    for series in ("I", "II"):
        part = rows.subset(rows.series == series)
        _write_rows(folder / f"{series}.csv", part, series, part.sample)
    (folder / "pooled.toml").write_text(
        'name = "pooled"\n'
        + _campaign_table("specular", "I.csv", "I", "images_per_row = 12")
        + _campaign_table("off", "II.csv", "II", off_errors)
        + (f"[errors]\n{shared}\n" if shared else "")
    )
    return folder / "pooled.toml"


def _covariance(model, sites) -> tuple[np.ndarray, np.ndarray]:
    parts = model.draw_parts(sites)
    factor = np.asarray(parts.factor)
    dense = np.einsum("dik,djk->dij", factor, factor)
    dense += np.stack([np.diag(d) for d in np.asarray(parts.diagonal)])
    return np.asarray(parts.mean), dense


def _uv_sites(model, count: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(3)
    values = {"dphi_scale": 1.0, **params_to_dict(UV_PAPER)}
    sites = {
        name: values[name] * np.exp(rng.normal(0.0, 0.05, count))
        for name in model.family.parameters
    }
    sites["sample_sd"] = rng.uniform(0.02, 0.2, count)
    sites["repeatability"] = rng.uniform(0.01, 0.1, count)
    return sites


def test_the_bundled_rows_as_two_campaigns_have_the_likelihood_of_the_bundled_scene(tmp_path):
    """Series I and II of ``lya`` as two campaign files with the data options ``lya`` gives
    them (12 images a row in series I, a 6.5 % calibration per series): the rows' mean and
    covariance D + W Wᵀ at five draws are the bundled scene's to rounding. A campaign's own
    calibration (3 % for series II, the planted difference) changes exactly the covariance of
    that campaign's rows."""
    lya = load_scene("lya")
    reference = build_posterior_model(lya, lya.load_measurements())
    pooled = load_scene(_lya_split(tmp_path))
    model = build_posterior_model(pooled, pooled.load_measurements())
    sites = _uv_sites(model, 5)
    mean, covariance = _covariance(model, sites)
    reference_mean, reference_covariance = _covariance(reference, sites)
    assert_allclose(mean, reference_mean, rtol=1e-12)
    assert_allclose(covariance, reference_covariance, rtol=1e-12, atol=1e-15)

    changed = load_scene(_lya_split(tmp_path, off_errors="calibration_rel = 0.03"))
    other = build_posterior_model(changed, changed.load_measurements())
    _, changed_covariance = _covariance(other, sites)
    off = changed.load_measurements().series == "off/II"
    difference = changed_covariance - reference_covariance
    assert_allclose(difference[:, off][:, :, off], np.full((5, 18, 18), 0.03**2 - 0.065**2))
    assert not np.any(difference[:, ~off]) and not np.any(difference[:, :, ~off])


def test_each_campaign_row_carries_its_campaigns_data_options(tmp_path):
    """The noise layout takes each row's σ_i, σ_cal, the rotation coupling and the angle
    scales from its campaign: 12 images a row, a calibration per sample, the camera fixed and
    2° angles in one campaign, the scene's defaults in the other."""
    scene = load_scene(
        _lya_split(
            tmp_path,
            off_errors='calibration = "per_sample"\ncalibration_rel = 0.1\n'
            'rotation_coupling = "camera_fixed"\nangle_deg = 2.0',
            shared="calibration_rel = 0.05",
        )
    )
    rows = scene.load_measurements()
    layout = noise_layout(scene.errors, rows)
    off = rows.series == "off/II"
    relative = rows.reflectance_err / rows.reflectance
    assert_allclose(np.asarray(layout.sigma_row)[~off], relative[~off] / np.sqrt(12))
    assert_allclose(np.asarray(layout.sigma_row)[off], relative[off])
    assert_allclose(np.asarray(layout.calibration_sd), np.where(off, 0.1, 0.05))
    assert_allclose(np.asarray(layout.theta_s_per_rotation), np.where(off, -1.0, 1.0))
    for name in ("rotation_deg", "camera_deg"):
        assert_allclose(np.asarray(getattr(layout, name)), np.where(off, 2.0, 1.0))
    assert calibration_group_names(scene.errors, rows) == ["specular/I", "off/II, off/40x40"]


@pytest.mark.parametrize(
    ("text", "field"),
    [
        ('measurements = "I.csv"\n' + _campaign_table("a", "I.csv", "I"), "measurements"),
        (_campaign_table("a", "I.csv", "I") + "[campaigns.a.bsdf]\n[campaigns.a.x]\n", None),
        (_campaign_table("a", "I.csv", "I", "hierarchical = false"), "hierarchical"),
        (_campaign_table("a", "I.csv", "I", "calibration_rel = -1"), "calibration_rel"),
        (_campaign_table("a", "I.csv", "I", "images_per_row = { II = 3 }"), "II"),
        ('[campaigns.a]\nmeasurements = "I.csv"\n[campaigns.a.series.I]\n', "aperture"),
        ('[campaigns."a/b"]\nmeasurements = "I.csv"\n', "campaigns.a/b"),
        ("campaigns = 3\n", "campaigns"),
    ],
)
def test_a_malformed_campaign_is_refused_naming_its_field(tmp_path, text, field):
    """Each mistake is one error naming the scene file and the field under
    ``campaigns.NAME`` (a key that is not a data option, a bad value, a series the campaign
    does not have, a name with '/')."""
    _lya_split(tmp_path)
    (tmp_path / "bad.toml").write_text('name = "bad"\n' + text)
    with pytest.raises(BadInputError) as caught:
        load_scene(tmp_path / "bad.toml")
    error = caught.value
    assert error.file == str(tmp_path / "bad.toml")
    if field == "measurements":
        assert error.field == "measurements"
    elif field is None:
        assert error.field == "campaigns.a.x"
    else:
        assert str(error.field).startswith("campaigns") and field in str(error.field)


def test_a_missing_campaign_file_exits_2_naming_the_campaign(tmp_path, capsys):
    """``brdf-infer posterior`` on a pooled scene whose second campaign's file is missing: exit 2,
    one line naming ``campaigns.off.measurements``, no traceback, nothing written."""
    scene = _lya_split(tmp_path)
    (tmp_path / "II.csv").unlink()
    code, _, err = run_cli("posterior", str(scene), "--out", str(tmp_path / "out"), capsys=capsys)
    assert code == 2
    assert "campaigns.off.measurements" in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_the_calibration_factors_conditional_is_the_dense_gaussian_conditional(tmp_path):
    """κ | θ, y of the two campaigns' calibration groups from the low-rank conjugate formula
    against the joint normal of (κ, y) written out densely (Cov(κ_g, y_i) = σ_g² for the
    rows of group g), at three draws, with different σ_cal per campaign and the angle errors
    off (so that W holds samples and calibrations only)."""
    from brdf_infer.posterior._targets import effect_moments

    path = _lya_split(
        tmp_path, off_errors="calibration_rel = 0.2", shared="propagate_angles = false"
    )
    scene = load_scene(path)
    model = build_posterior_model(scene, scene.load_measurements())
    sites = {k: v[None, :3] for k, v in _uv_sites(model, 3).items()}
    *_, mean, covariance = effect_moments(model, sites)
    groups = scene.load_measurements().series
    names = ["specular/I", "off/II"]
    scale = np.array([0.065, 0.2])
    samples = np.asarray(model.row_samples)
    sigma = np.asarray(model.data.noise.sigma_row)
    for k in range(3):
        tau, repeat = sites["sample_sd"][0, k], sites["repeatability"][0, k]
        one_hot = (groups[None, :] == np.array(names)[:, None]).astype(float)
        cov_y = (
            np.diag(sigma**2 + repeat**2)
            + tau**2 * (samples[:, None] == samples[None, :])
            + (one_hot * scale[:, None] ** 2).T @ one_hot
        )
        cov_ky = one_hot * scale[:, None] ** 2
        point = {n: v[0, k : k + 1] for n, v in sites.items()}
        residual = np.asarray(model.data.rows.log_reflectance) - np.asarray(
            model.draw_parts(point).mean[0]
        )
        gain = cov_ky @ np.linalg.inv(cov_y)
        assert_allclose(mean[k], gain @ residual, rtol=0, atol=1e-10)
        assert_allclose(covariance[k], np.diag(scale**2) - gain @ cov_ky.T, rtol=0, atol=1e-12)


# ---------------------------------------------------------------- two simulated campaigns

TRUE_CALIBRATION = {"labA": 0.08, "labB": -0.15}  # the realised κ of each campaign [ln R]
CALIBRATION_SD = {"labA": 0.1, "labB": 0.2}  # each campaign's stated σ_cal
TRUE_TAU = 0.05


def _simulated_campaigns(folder: Path, noise_b: float = 0.03) -> Path:
    """Two campaigns of series II's geometry (three samples in labA, two in labB), with
    their calibrations 10 % and 20 %, drawn from Eqs. (7)–(8) at the UV parameters: each row
    the clean value × e^(κ_campaign + u_sample + e_row), u ~ N(0, 5 %), e ~ N(0, 3 %) as
    each row's σ states (labB's e ~ N(0, ``noise_b``): a planted misfit where it is not 3 %),
    the angle errors off."""
    folder.mkdir(exist_ok=True)
    lya = load_scene("lya")
    rows = lya.load_measurements()
    template = rows.subset(rows.series == "II")
    clean = synthetic_measurements(lya, template, UV_PAPER, noise_rel=0.0)
    rng = np.random.default_rng(11)
    text = 'name = "two-labs"\n[errors]\npropagate_angles = false\n'
    for lab, samples in (("labA", 3), ("labB", 2)):
        values, errors, names = [], [], []
        for sample in range(samples):
            effect = rng.normal(0.0, TRUE_TAU)
            noise = rng.normal(0.0, noise_b if lab == "labB" else 0.03, len(template))
            shift = TRUE_CALIBRATION[lab] + effect + noise
            values.append(clean.reflectance * np.exp(shift))
            errors.append(0.03 * values[-1])
            names += [f"s{sample}"] * len(template)
        stacked = template.subset(np.tile(np.arange(len(template)), samples))
        stacked = type(stacked)(
            **{
                **stacked.__dict__,
                "reflectance": np.concatenate(values),
                "reflectance_err": np.concatenate(errors),
            }
        )
        _write_rows(folder / f"{lab}.csv", stacked, "II", names)
        text += _campaign_table(lab, f"{lab}.csv", "II", f"calibration_rel = {CALIBRATION_SD[lab]}")
    (folder / "two.toml").write_text(text)
    return folder / "two.toml"


@pytest.mark.slow  # ≈ 40 s: a NUTS run of 90 rows
def test_two_simulated_campaigns_recover_the_coating_and_learn_each_calibration(tmp_path, capsys):
    """Two campaigns of one coating with different calibrations (10 %, 20 %), pooled: the
    coating's learned parameters and τ inside their 95 % intervals, each campaign's realised
    calibration factor inside its interval and learned (posterior sd below its prior σ_cal:
    what the rows locate is the difference of the two, so the wider prior is the one the
    rows narrow most), the campaigns' elpd summing to the run's, and the model check passing;
    a 40 % offset of labB beyond its 20 % calibration (the planted misfit) fails the check."""
    scene = _simulated_campaigns(tmp_path)
    code, _, err = run_cli("posterior", str(scene), "--out", str(tmp_path / "run"), capsys=capsys)
    assert code == 0, err
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    truth = {"brdf0": UV_PAPER.brdf0, "alpha": UV_PAPER.alpha, "sample_sd": TRUE_TAU}
    posterior = az.from_netcdf(tmp_path / "run" / "posterior.nc").posterior
    for name, value in truth.items():
        low, high = np.quantile(np.asarray(posterior[name]), [0.025, 0.975])
        assert low < value < high, (name, low, value, high)
    effects = {entry["name"].split("/")[0]: entry for entry in summary["calibration_effects"]}
    for lab, value in TRUE_CALIBRATION.items():
        entry = effects[lab]
        assert entry["lo95"] < value < entry["hi95"], (lab, entry)
        assert entry["sd_ratio"] < 1.0, (lab, entry)
    assert effects["labB"]["sd_ratio"] < 0.7
    # docs/posterior.md's table quotes this run: each κ median within 4.5 Monte Carlo errors
    quoted = {"labA": (0.047, 0.87), "labB": (-0.182, 0.54)}
    kappa = np.asarray(posterior["calibration_effect"])
    for g, lab in enumerate(("labA", "labB")):
        se = mcmc_quantile_se(kappa[..., g], 0.5)
        assert abs(effects[lab]["median"] - quoted[lab][0]) < MC_BOUND * se + 5e-4, lab
        assert abs(effects[lab]["sd_ratio"] - quoted[lab][1]) < 0.05, lab
    campaigns = summary["campaigns"]
    assert [c["rows"] for c in campaigns.values()] == [54, 36]
    total = sum(c["elpd_loo"] for c in campaigns.values())
    assert_allclose(total, summary["predictive"]["elpd_loo"], rtol=1e-9)
    assert summary["model_check"]["ok"], summary["model_check"]

    planted = _simulated_campaigns(tmp_path / "planted", noise_b=0.3)
    code, _, err = run_cli("posterior", str(planted), "--out", str(tmp_path / "bad"), capsys=capsys)
    assert code == 0, err
    checks = json.loads((tmp_path / "bad" / "summary.json").read_text())["model_check"]["checks"]
    assert not next(c for c in checks if c["name"] == "loo_pit_campaigns")["ok"]


@pytest.mark.slow  # ≈ 2 × 65 s: SBC at 100 replicates
@pytest.mark.parametrize("planted", [False, True], ids=["as built", "factors moved by σ_cal"])
def test_the_pooled_model_is_calibrated_with_each_calibration_factor(
    tmp_path, monkeypatch, planted
):
    """SBC of the two simulated campaigns (100 replicates): every parameter, the three
    targets' TIS(70°) and both calibration factors rank uniformly. With the posterior's
    calibration factors moved by their σ_cal (the planted fault) their ranks fail."""
    from brdf_infer.scene.settings import SbcSettings
    from brdf_infer.studies import sbc as sbc_module

    if planted:
        original = sbc_module.latent_effect_draws

        def moved(model, sites, seed, data=None):
            effects, calibration = original(model, sites, seed, data)
            if len(effects) == 1:  # the truth's
                return effects, calibration
            return effects, calibration + np.array([CALIBRATION_SD[lab] for lab in CALIBRATION_SD])

        monkeypatch.setattr(sbc_module, "latent_effect_draws", moved)
    scene = load_scene(_simulated_campaigns(tmp_path))
    result = sbc_module.run_sbc(scene, scene.load_measurements(), SbcSettings(replicates=100))
    assert {"calibration_1", "calibration_2"} <= set(result.ranks)
    if planted:
        assert any("calibration_" in line for line in result.failures), result.failures
    else:
        assert result.passed, result.failures
