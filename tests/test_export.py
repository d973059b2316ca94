"""Exports to ray tracers: Zemax .BSDF files checked with a reader written separately from the
writer (tests/independent_bsdf.py), the specular-frame geometry against that reader's own
derivation, the tables against the plain-Python model of tests/helpers.py, and ABg fits
against SciPy's adaptive quadrature of the ABg TIS."""

import json

import numpy as np
import pytest
from scipy import integrate

from brdf_infer.cli import main
from brdf_infer.errors import BadInputError
from brdf_infer.model.params import UV_PAPER
from brdf_infer.posterior import draws_params
from brdf_infer.report.export import (
    BsdfFile,
    read_bsdf,
    specular_frame_to_model,
    write_bsdf,
)
from tests import independent_bsdf as oracle
from tests.helpers import REDUCED_NUTS, reference_brdf_hemisphere, run_cli

COARSE = ["--azimuth-step", "15", "--radial-step", "5"]


def export_json(capsys, *argv):
    code, out, err = run_cli("export", *argv, "--json", capsys=capsys)
    assert code == 0, err
    return json.loads(out)


@pytest.fixture(scope="module")
def params_export(tmp_path_factory):
    """``export --params uv-paper --format zemax-bsdf`` with the default grid."""
    out = tmp_path_factory.mktemp("bsdf")
    assert main(["export", "--params", "uv-paper", "--out", str(out)]) == 0
    return out / "params.bsdf"


def test_params_file_is_strict_and_both_readers_agree(params_export):
    assert oracle.strictness_problems(params_export) == []
    theirs = oracle.read_bsdf(params_export)
    ours = read_bsdf(params_export)
    assert theirs["symmetry"] == ours.symmetry == "PlaneSymmetrical"
    np.testing.assert_array_equal(theirs["angle_of_incidence"], np.arange(0.0, 86.0, 5.0))
    np.testing.assert_array_equal(theirs["scatter_azimuth"], np.arange(0.0, 181.0, 5.0))
    np.testing.assert_array_equal(theirs["scatter_radial"], np.arange(0.0, 176.0, 1.0))
    np.testing.assert_array_equal(theirs["tis"], ours.tis)
    np.testing.assert_array_equal(theirs["bsdf"], ours.bsdf)
    assert any("uv-paper" in line for line in theirs["comments"])


def test_tis_lines_equal_the_tis_command(params_export, capsys):
    angles = [f"{t:g}" for t in np.arange(0.0, 86.0, 5.0)]
    code, out, err = run_cli(
        "tis", "--params", "uv-paper", "--theta-i", *angles, "--json", capsys=capsys
    )
    assert code == 0, err
    expected = np.array(json.loads(out)["tis"])
    np.testing.assert_allclose(oracle.read_bsdf(params_export)["tis"][0], expected, rtol=1e-10)


def test_tables_match_the_model_at_every_grid_direction(params_export):
    """Eqs. (7), (8), (10) in plain Python at each (AOI, azimuth, radial), through the oracle's
    own specular-frame geometry; 0 below the horizon."""
    contents = oracle.read_bsdf(params_export)
    for k, aoi in enumerate(contents["angle_of_incidence"]):
        table = contents["bsdf"][0, k]
        psi, radial = np.meshgrid(
            contents["scatter_azimuth"], contents["scatter_radial"], indexing="ij"
        )
        theta, phi, above = oracle.specular_frame_to_model(aoi, psi, radial)
        horizon = np.abs(np.cos(np.radians(theta))) < 1e-9  # either value is right there
        assert np.all(table[~above & ~horizon] == 0.0)
        for i, j in np.argwhere(above & ~horizon):
            expected = reference_brdf_hemisphere(aoi, theta[i, j], phi[i, j], UV_PAPER)
            assert table[i, j] == pytest.approx(expected, rel=2e-6), (aoi, psi[i, j], radial[i, j])


def test_each_table_integrates_to_its_tis_line_within_one_percent(params_export):
    contents = oracle.read_bsdf(params_export)
    for k, aoi in enumerate(contents["angle_of_incidence"]):
        integral = oracle.hemisphere_integral(
            aoi, contents["scatter_azimuth"], contents["scatter_radial"], contents["bsdf"][0, k]
        )
        assert integral == pytest.approx(contents["tis"][0, k], rel=0.01), aoi


@pytest.mark.parametrize("aoi", [0.0, 0.5, 30.0, 60.0, 85.0, 89.5])
def test_specular_frame_geometry_matches_the_independent_derivation(aoi):
    rng = np.random.default_rng(int(aoi * 10))
    psi = rng.uniform(0.0, 180.0, 400)
    radial = rng.uniform(0.0, 90.0 + aoi, 400)
    theta, phi, z = (np.asarray(v) for v in specular_frame_to_model(aoi, psi, radial))
    their_theta, their_phi, above = oracle.specular_frame_to_model(aoi, psi, radial)
    np.testing.assert_array_equal(z > 1e-12, above & (z > 1e-12))
    keep = (z > 1e-6) & (np.sin(np.radians(their_theta)) > 1e-6)
    np.testing.assert_allclose(theta[keep], their_theta[keep], atol=1e-9)
    np.testing.assert_allclose(np.mod(phi[keep], 360.0), their_phi[keep], atol=1e-9)


def test_write_then_read_gives_the_same_numbers(tmp_path):
    rng = np.random.default_rng(1)
    contents = BsdfFile(
        theta_i_deg=np.array([0.0, 45.0]),
        azimuth_deg=np.array([0.0, 90.0, 180.0]),
        radial_deg=np.array([0.0, 10.0, 135.0]),
        tis=rng.uniform(0.01, 0.1, (1, 2)),
        bsdf=rng.lognormal(-4.0, 2.0, (1, 2, 3, 3)),
        comments=["a comment"],
    )
    path = write_bsdf(tmp_path / "x.bsdf", contents)
    back = read_bsdf(path)
    np.testing.assert_allclose(back.bsdf, contents.bsdf, rtol=1e-6)
    np.testing.assert_allclose(back.tis, contents.tis, rtol=1e-10)
    assert back.comments == ["a comment"] and oracle.strictness_problems(path) == []


GOOD = """# a comment
Source Measured
Symmetry PlaneSymmetrical
SpectralContent Monochrome
ScatterType BRDF
SampleRotation 1
0
AngleOfIncidence 1
0
ScatterAzimuth 2
0\t180
ScatterRadial 2
0\t90

Monochrome
DataBegin
TIS 0.31830989
0.1\t0.1
0.1\t0.1
DataEnd
"""


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (("DataEnd\n", ""), "'DataEnd'"),
        (("ScatterRadial 2", "ScatterRadial 3"), "line 13: ScatterRadial: expected 3 values"),
        (("0.1\t0.1\nDataEnd", "0.1\tx\nDataEnd"), "line 19: BSDF row: 'x' is not a number"),
        (("Monochrome\nScatterType", "Tristimulus\nScatterType"), "line 4: SpectralContent"),
        (("TIS 0.31830989\n", ""), "line 17: expected 'TIS <value>'"),
        (("0.1\t0.1\nDataEnd", "0.1\nDataEnd"), "line 19: BSDF row: expected 2 values"),
        (("Symmetry PlaneSymmetrical", "Symmetry Round"), "line 3: Symmetry must be"),
    ],
)
def test_malformed_bsdf_files_are_one_line_and_exit_2(tmp_path, capsys, change, match):
    path = tmp_path / "bad.bsdf"
    assert GOOD.count(change[0]) == 1
    path.write_text(GOOD.replace(*change))
    code, out, err = run_cli("export", "--check", str(path), capsys=capsys)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and str(path) in err and match in err, err


def test_other_tools_files_tabs_and_header_order_are_read(tmp_path):
    """Words separated by tabs only, and header lines in another order (as other tools write
    them), read as the tidy file (found by the generated inputs: a tab after a keyword was
    refused)."""
    from brdf_infer.report.export import read_bsdf

    tidy, untidy = tmp_path / "tidy.bsdf", tmp_path / "untidy.bsdf"
    tidy.write_text(GOOD)
    lines = GOOD.replace("Source Measured", "Source\tMeasured").splitlines()
    lines = [line.replace(" ", "\t") for line in lines if not line.startswith("#")]
    header = lines[:14]
    header = header[4:8] + header[:4] + header[12:14] + header[8:12]  # counted ones, keywords
    untidy.write_text("\n".join(header + lines[14:]) + "\n")
    ours, theirs = read_bsdf(untidy), read_bsdf(tidy)
    for name in ("theta_i_deg", "azimuth_deg", "radial_deg", "tis", "bsdf"):
        np.testing.assert_array_equal(getattr(ours, name), getattr(theirs, name))
    assert (ours.symmetry, ours.scatter_type, ours.source) == (
        "PlaneSymmetrical",
        "BRDF",
        "Measured",
    )
    untidy.write_text(GOOD.replace("SampleRotation 1\n0\n", ""))
    with pytest.raises(BadInputError, match="line 14: the header lacks 'SampleRotation'"):
        read_bsdf(untidy)


def test_a_direction_listed_twice_is_one_measurement_row(tmp_path):
    """Radial 0 is the specular ray in every azimuth row: one row, not one per azimuth (a
    CSV may not repeat a row either); an angle of incidence of 90° or more is refused."""
    from brdf_infer.tables.bsdf_measurements import measurements_from_bsdf

    path = tmp_path / "t.bsdf"
    path.write_text(GOOD.replace("AngleOfIncidence 1\n0", "AngleOfIncidence 1\n20"))
    rows = measurements_from_bsdf(path)
    # azimuth 0 and 180 at radial 0: the specular ray twice (one row); radial 90 at azimuth
    # 0 is θs = −70°, at azimuth 180 below the horizon
    np.testing.assert_allclose(rows.theta_s_deg, [20.0, -70.0], rtol=1e-12)
    path.write_text(GOOD.replace("AngleOfIncidence 1\n0", "AngleOfIncidence 1\n95"))
    with pytest.raises(BadInputError, match="field 'AngleOfIncidence': angles of incidence"):
        measurements_from_bsdf(path)


def test_check_reads_a_good_file_and_integrates_it(tmp_path, capsys):
    path = tmp_path / "good.bsdf"
    path.write_text(GOOD)
    payload = export_json(capsys, "--check", str(path))
    assert payload["tis"] == [[0.31830989]] and payload["radial_deg"] == [0.0, 90.0]
    code, _, err = run_cli("export", "--check", str(tmp_path / "none.bsdf"), capsys=capsys)
    assert code == 2 and "no such file" in err


def test_posterior_exports_are_ordered_and_their_tis_lines_are_the_tis_band(
    nuts_run, tmp_path, capsys
):
    angles = ["0", "30", "60", "85"]
    payload = export_json(
        capsys, "--run", str(nuts_run.out), "--theta-i", *angles, *COARSE, "--draws", "2",
        "--out", str(tmp_path),
    )  # fmt: skip
    kinds = [f["kind"] for f in payload["files"]]
    assert (
        kinds == ["lower95", "median", "upper95", "tis_q025", "tis_q500", "tis_q975"] + ["draw"] * 2
    )
    tables = {f["kind"]: oracle.read_bsdf(f["path"]) for f in payload["files"][:3]}
    lower, median, upper = (tables[k]["bsdf"] for k in ("lower95", "median", "upper95"))
    assert np.all(lower <= median) and np.all(median <= upper)
    assert np.any(lower < upper)
    code, out, err = run_cli(
        "tis", "--run", str(nuts_run.out), "--theta-i", *angles, "--json", capsys=capsys
    )
    assert code == 0, err
    band = json.loads(out)
    for kind, key in (("lower95", "lo95"), ("median", "median"), ("upper95", "hi95")):
        np.testing.assert_allclose(tables[kind]["tis"][0], band[key], rtol=1e-10)
    # a draw file is one consistent BRDF: its TIS lines are its own exact TIS, at its own
    # out-of-plane width (Δφ × the draw's dphi_scale)
    draws = draws_params(nuts_run.idata.posterior)
    from brdf_infer.model import tis
    from brdf_infer.model.params import PAPER_CONSTANTS, with_dphi_scale

    first = type(draws)(*(float(v[0]) for v in draws))
    scale = float(np.asarray(nuts_run.idata.posterior["dphi_scale"]).reshape(-1)[0])
    constants = with_dphi_scale(PAPER_CONSTANTS, scale)
    np.testing.assert_allclose(
        oracle.read_bsdf(payload["files"][6]["path"])["tis"][0],
        np.asarray(tis(np.array([0.0, 30.0, 60.0, 85.0]), first, False, constants)),
        rtol=1e-10,
    )


def _abg_tis_scipy(a: float, b: float, g: float, aoi: float) -> float:
    """A·∫∫ d²β / (B + |β − β₀|^g) over the unit disk, by SciPy in polar coordinates about
    the origin (independent of the package's polar-about-β₀ Gauss–Legendre)."""
    beta0 = -np.sin(np.radians(aoi))

    def integrand(r, t):
        return r / (b + np.hypot(r * np.cos(t) - beta0, r * np.sin(t)) ** g)

    value, _ = integrate.dblquad(integrand, 0.0, 2 * np.pi, 0.0, 1.0, epsabs=0.0, epsrel=1e-10)
    return a * value


@pytest.mark.full
def test_abg_fits_preserve_the_tis_and_report_their_error(tmp_path, capsys):
    payload = export_json(
        capsys, "--params", "uv-paper", "--format", "abg", "--theta-i", "0", "40", "80",
        "--out", str(tmp_path),
    )  # fmt: skip
    rows = payload["rows"]
    assert [r["theta_i_deg"] for r in rows] == [0.0, 40.0, 80.0]
    for row in rows:
        assert row["tis_abg"] == pytest.approx(row["tis_model"], rel=1e-6)
        independent = _abg_tis_scipy(row["A"], row["B"], row["g"], row["theta_i_deg"])
        assert independent == pytest.approx(row["tis_model"], rel=1e-6)
        assert 0.0 < row["rms_log_error"] < 1.0
    # near normal incidence ABg is a good stand-in, near grazing it is not
    assert rows[0]["rms_log_error"] < 0.1 < rows[2]["rms_log_error"]
    header = (tmp_path / "abg.csv").read_text().splitlines()[0]
    assert header == "theta_i_deg,A,B,g,tis_model,tis_abg,rms_log_error"
    stored = json.loads((tmp_path / "abg.json").read_text())
    assert stored["rows"] == rows and stored["fold"] is False and payload["fold"] is False
    assert stored["folding"].startswith("Eq. (10) folding: not included (physical BRDF")


def test_abg_over_posterior_draws_gives_intervals(nuts_run, tmp_path, capsys):
    payload = export_json(
        capsys, "--run", str(nuts_run.out), "--format", "abg", "--theta-i", "20", "70",
        "--draws", "4", "--out", str(tmp_path),
    )  # fmt: skip
    for row in payload["rows"]:
        for name in ("A", "B", "g", "tis_model", "tis_abg"):
            assert row[f"{name}_lo95"] <= row[name] <= row[f"{name}_hi95"]
        assert row["tis_abg"] == pytest.approx(row["tis_model"], rel=1e-6)


def test_more_draws_than_the_run_has_is_a_clear_error(nuts_run, tmp_path, capsys):
    out = tmp_path / "out"
    argv = ["export", "--run", str(nuts_run.out), "--draws", "100000", "--out", str(out)]
    code, _, err = run_cli(*argv, capsys=capsys)
    draws = f"{4 * REDUCED_NUTS['draws']} draws"
    assert code == 2 and "--draws" in err and draws in err and not out.exists()


@pytest.mark.full
def test_a_grid_too_coarse_for_its_tis_is_warned_about(tmp_path, capsys):
    """Planted fault for the table-integral check: 45° azimuth and 10° radial steps miss the
    TIS by 17 % at θi = 85°."""
    argv = ["--params", "uv-paper", "--theta-i", "0", "85", "--azimuth-step", "45"]
    code, _, err = run_cli("export", *argv, "--radial-step", "10", "--out", str(tmp_path / "a"),
                           capsys=capsys)  # fmt: skip
    assert code == 0 and "misses its TIS" in err
    code, _, err = run_cli("export", *argv[:4], "--out", str(tmp_path / "b"), capsys=capsys)
    assert code == 0 and "misses its TIS" not in err


def test_existing_files_are_kept_without_force(tmp_path, capsys):
    argv = ["--params", "uv-paper", "--theta-i", "10", *COARSE, "--out", str(tmp_path)]
    export_json(capsys, *argv)
    before = (tmp_path / "params.bsdf").read_bytes()
    code, _, err = run_cli("export", "--params", "vis-paper", *argv[2:], capsys=capsys)
    assert code == 2 and "--force" in err
    assert (tmp_path / "params.bsdf").read_bytes() == before
    export_json(capsys, "--params", "vis-paper", *argv[2:], "--force")
    assert (tmp_path / "params.bsdf").read_bytes() != before


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--params", "uv-paper", "--draws", "3"], "--draws"),
        (["--params", "uv-paper", "--radial-step", "0"], "--radial-step"),
        (["--params", "uv-paper", "--theta-i", "90"], "--theta-i"),
        (["--params", "nowhere.json"], "nowhere.json"),
        (["--run", "no-such-run"], "posterior.nc"),
    ],
)
def test_bad_export_options_create_nothing(tmp_path, capsys, argv, match):
    out = tmp_path / "out"
    code, stdout, err = run_cli("export", *argv, "--out", str(out), capsys=capsys)
    assert code == 2 and stdout == "" and match in err and err.count("\n") == 1, err
    assert not out.exists()
