"""Other data shapes: BRDF rows (no aperture), out-of-plane rows (φs), and a tabular .BSDF file
as the measurements; fits and posteriors recover the parameters that made the data."""

from __future__ import annotations

import json

import jax.numpy as jnp
import numpy as np
import pytest

from brdf_infer.errors import BadInputError
from brdf_infer.fit.lsq import fit_lsq
from brdf_infer.model import brdf_hemisphere, family
from brdf_infer.model.params import UV_PAPER
from brdf_infer.posterior import run_posterior
from brdf_infer.scene import load_scene
from brdf_infer.studies.compare import CompareSettings, fit_family
from tests.helpers import run_cli

ERRORS = (
    "[errors]\nreflectance_rel = 0.05\npropagate_angles = false\nhierarchical = false\n"
    "repeatability = 0.0\n"
)
ABG_TRUTH = {"A": 3.0e-3, "B": 4.0e-2, "g": 1.6}


def _geometry():
    """θi ∈ {10, 30, 50, 70}; θ ∈ {5, 25, 45, 65, 80}; φ ∈ {0, 60, 120, 150, 180, 210, 300}."""
    grid = np.array(
        [
            (ti, th, ph)
            for ti in (10.0, 30.0, 50.0, 70.0)
            for th in (5.0, 25.0, 45.0, 65.0, 80.0)
            for ph in (0.0, 60.0, 120.0, 150.0, 180.0, 210.0, 300.0)
        ]
    )
    return grid[:, 0], grid[:, 1], grid[:, 2]


def write_brdf_scene(tmp_path, brdf: np.ndarray, extra: str = "") -> object:
    """A scene of BRDF rows (one sample) with 5 % log-normal noise on ``brdf``."""
    theta_i, theta, phi = _geometry()
    noisy = brdf * np.exp(np.random.default_rng(11).normal(0.0, 0.05, brdf.shape))
    lines = ["series,sample,theta_i_deg,theta_s_deg,phi_s_deg,brdf"]
    lines += [
        f"S,a,{ti:g},{th:g},{ph:g},{value:.8e}"
        for ti, th, ph, value in zip(theta_i, theta, phi, noisy, strict=True)
    ]
    (tmp_path / "rows.csv").write_text("\n".join(lines) + "\n")
    (tmp_path / "brdf.toml").write_text(
        f'name = "brdf-rows"\nmeasurements = "rows.csv"\n{extra}[series.S]\n'
        f'quantity = "brdf"\n[model]\nfold = true\n{ERRORS}'
    )
    return load_scene(tmp_path / "brdf.toml")


def test_brdf_rows_out_of_plane_are_read_with_their_azimuth(tmp_path):
    theta_i, theta, phi = _geometry()
    scene = write_brdf_scene(tmp_path, np.full(theta_i.shape, 0.02))
    rows = scene.load_measurements()
    assert rows.quantity == "brdf" and len(rows) == theta_i.size
    in_plane = (phi == 0.0) | (phi == 180.0)
    assert np.array_equal(rows.out_of_plane, ~in_plane)
    assert np.array_equal(rows.theta_s_deg[phi == 0.0], -theta[phi == 0.0])  # backward: −θ
    assert np.array_equal(rows.theta_s_deg[phi == 180.0], theta[phi == 180.0])
    assert np.all(scene.log_conversion(rows) == 0.0)  # BRDF rows: no aperture, no cos θs


@pytest.mark.slow  # a posterior on a large out-of-plane table
def test_lsq_and_posterior_recover_strumik2024_from_out_of_plane_brdf_rows(tmp_path):
    theta_i, theta, phi = _geometry()
    truth = np.asarray(brdf_hemisphere(theta_i, theta, phi, UV_PAPER, True))
    scene = write_brdf_scene(tmp_path, truth)
    rows = scene.load_measurements()
    fit = fit_lsq(scene, rows, starts=8)
    for name in ("brdf0", "alpha", "theta_s0", "a1"):
        error = getattr(fit.params, name) - getattr(UV_PAPER, name)
        assert abs(error) < 4.0 * fit.sigma[name], (name, error, fit.sigma[name])
    run = run_posterior(scene, rows, chains=2, draws=300, warmup=300, seed=2)
    posterior = run.idata.posterior
    for name in ("brdf0", "alpha", "theta_s0"):
        low, high = np.quantile(np.asarray(posterior[name]), [0.005, 0.995])
        assert low <= getattr(UV_PAPER, name) <= high, name


FAMILY_TRUTHS = {
    "abg": ABG_TRUTH,
    "harvey-shack": {"b0": 0.3, "L": 0.1, "S": -2.0},
    "lambertian": {"tis": 0.05},
    "lambertian+abg": {"rho_d": 0.02, **ABG_TRUTH},
}


@pytest.mark.parametrize(
    "name",
    [
        # ≈ 15-30 s each with a cold compilation cache (a sampler per family and table shape):
        # with the slow tests; the suite reads a .BSDF table as measurements and fits it
        # (test_a_bsdf_table_as_measurements_returns_the_parameters_that_made_it)
        pytest.param("abg", marks=pytest.mark.slow),
        pytest.param("lambertian", marks=pytest.mark.slow),
        pytest.param("harvey-shack", marks=pytest.mark.slow),
        pytest.param("lambertian+abg", marks=pytest.mark.slow),
    ],
)
def test_every_family_is_recovered_from_out_of_plane_brdf_rows_by_lsq_and_nuts(tmp_path, name):
    theta_i, theta, phi = _geometry()
    member = family(name)
    truth = FAMILY_TRUTHS[name]
    physical = {k: jnp.asarray(v) for k, v in truth.items()}
    scene = write_brdf_scene(
        tmp_path, np.exp(np.asarray(member.log_brdf(theta_i, theta, phi, physical)))
    )
    rows = scene.load_measurements()
    fit = fit_lsq(scene, rows, member, starts=8)
    for parameter, value in truth.items():
        error = fit.physical[parameter] - value
        assert abs(error) < 4.0 * fit.sigma[parameter], (parameter, fit.physical, fit.sigma)
    result = fit_family(scene, rows, name, CompareSettings(chains=2, warmup=300, draws=300))
    posterior = result.idata.posterior
    for parameter, value in truth.items():
        low, high = np.quantile(np.asarray(posterior[parameter]), [0.001, 0.999])
        assert low <= value <= high, (parameter, low, high)


@pytest.mark.full
def test_a_bsdf_table_as_measurements_returns_the_parameters_that_made_it(tmp_path, capsys):
    """Export a parameter set as .BSDF, read it back as a scene's measurements (with trailing
    tabs on header lines, as vendor files have them) and fit: the parameters come back to the
    file's 7 significant digits. The table folds by Eq. (10) like a scatterometer's (the
    export's ``--fold``), and so does the scene that reads it."""
    code, _, err = run_cli(
        "export",
        "--params",
        "uv-paper",
        "--fold",
        "--theta-i",
        "0",
        "20",
        "40",
        "60",
        "80",
        "--azimuth-step",
        "15",
        "--radial-step",
        "5",
        "--out",
        str(tmp_path / "exp"),
        capsys=capsys,
    )
    assert code == 0, err
    text = (tmp_path / "exp" / "params.bsdf").read_text()
    untidy = "\n".join(
        line + "\t" if line.split(" ")[0] in ("Symmetry", "AngleOfIncidence") else line
        for line in text.splitlines()
    )
    (tmp_path / "vendor.bsdf").write_text(untidy + "\n")
    (tmp_path / "s.toml").write_text(
        f'name = "vendor"\nmeasurements = "vendor.bsdf"\n[model]\nfold = true\n{ERRORS}'
    )
    scene = load_scene(tmp_path / "s.toml")
    rows = scene.load_measurements()
    assert set(rows.series) == {"bsdf"} and rows.quantity == "brdf"
    assert np.all(rows.theta_s_deg[~rows.out_of_plane] >= -90.0)
    assert np.all((rows.theta_s_deg >= 0.0) | ~rows.out_of_plane)
    fit = fit_lsq(scene, rows, starts=4)
    for name in ("brdf0", "a1", "alpha", "theta_s0"):
        assert getattr(fit.params, name) == pytest.approx(getattr(UV_PAPER, name), rel=1e-5)
    (tmp_path / "thin.toml").write_text(
        f'name = "thin"\nmeasurements = "vendor.bsdf"\n[bsdf]\nkeep_every_radial = 3\n'
        f"keep_every_azimuth = 2\n{ERRORS}"
    )
    assert len(load_scene(tmp_path / "thin.toml").load_measurements()) < len(rows) / 4


@pytest.mark.parametrize(
    ("header", "row", "field", "message"),
    [
        (
            "series,sample,theta_i_deg,theta_s_deg,reflectance,brdf",
            "S,a,10,20,0.1,0.1",
            "brdf",
            "one quantity",
        ),
        ("series,sample,theta_i_deg,theta_s_deg,brdf", "S,a,10,20,-0.1", "brdf", "> 0"),
        (
            "series,sample,theta_i_deg,theta_s_deg,phi_s_deg,brdf",
            "S,a,10,-20,90,0.1",
            "theta_s_deg",
            "polar angle",
        ),
        (
            "series,sample,theta_i_deg,theta_s_deg,reflectance",
            "S,a,10,20,0.01",
            "reflectance",
            "measures brdf",
        ),
    ],
)
def test_bad_measurement_kinds_are_named_by_file_row_and_field(
    tmp_path, capsys, header, row, field, message
):
    (tmp_path / "rows.csv").write_text(f"{header}\n{row}\n")
    (tmp_path / "s.toml").write_text(
        'name = "x"\nmeasurements = "rows.csv"\n[series.S]\nquantity = "brdf"\n'
    )
    with pytest.raises(BadInputError, match=message) as error:
        load_scene(tmp_path / "s.toml")
    assert error.value.field == field
    code, out, err = run_cli("fit", str(tmp_path / "s.toml"), "--method", "lsq", capsys=capsys)
    assert code == 2 and out == "" and "rows.csv" in err and "Traceback" not in err


def test_bsdf_scene_keys_are_checked(tmp_path):
    (tmp_path / "s.toml").write_text(
        'name = "x"\nmeasurements = "t.bsdf"\n[bsdf]\nkeep_every_radial = 0\n'
    )
    with pytest.raises(BadInputError, match="integer >= 1") as error:
        load_scene(tmp_path / "s.toml", check_files=False)
    assert error.value.field == "bsdf.keep_every_radial"
    assert json.dumps(str(error.value))


@pytest.mark.parametrize(
    "name",
    [
        pytest.param("abg", marks=pytest.mark.slow),
        pytest.param("lambertian+abg", marks=pytest.mark.slow),
    ],
)
def test_a_bsdf_table_of_another_family_is_fitted_and_sampled_back(tmp_path, name):
    """A .BSDF file tabulating a family's BRDF (a vendor's ABg table, say), read as a scene's
    measurements (thinned): lsq returns its parameters, NUTS covers them."""
    from brdf_infer.report.export import BsdfFile, specular_frame_to_model, write_bsdf

    member = family(name)
    truth = FAMILY_TRUTHS[name]
    physical = {k: jnp.asarray(v) for k, v in truth.items()}
    aoi = np.array([0.0, 30.0, 60.0])
    azimuth = np.arange(0.0, 181.0, 15.0)
    radial = np.arange(0.0, 91.0, 5.0)
    grid_azimuth, grid_radial = np.meshgrid(azimuth, radial, indexing="ij")
    tables = []
    for theta_i in aoi:
        theta, phi, z = specular_frame_to_model(theta_i, grid_azimuth, grid_radial)
        values = np.exp(np.asarray(member.log_brdf(theta_i, theta, phi, physical)))
        tables.append(np.where(np.asarray(z) > 0, values, 0.0))
    tis = [float(member.tis(jnp.asarray(t), physical)) for t in aoi]
    write_bsdf(
        tmp_path / "vendor.bsdf",
        BsdfFile(aoi, azimuth, radial, np.array([tis]), np.array([tables])),
    )
    (tmp_path / "s.toml").write_text(
        f'name = "vendor"\nmeasurements = "vendor.bsdf"\n[bsdf]\nkeep_every_radial = 2\n{ERRORS}'
    )
    scene = load_scene(tmp_path / "s.toml")
    rows = scene.load_measurements()
    fit = fit_lsq(scene, rows, member, starts=8)
    for parameter, value in truth.items():
        assert fit.physical[parameter] == pytest.approx(value, rel=1e-4), parameter
    result = fit_family(scene, rows, name, CompareSettings(chains=1, warmup=200, draws=200))
    for parameter, value in truth.items():
        low, high = np.quantile(np.asarray(result.idata.posterior[parameter]), [0.001, 0.999])
        assert low <= value * (1 + 1e-4) and value * (1 - 1e-4) <= high, parameter
