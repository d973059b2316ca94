"""A posterior run of another model family writes the same run folder as ``strumik2024``, and
every reader of a run folder (``tis --run``, ``export --run``, ``report``, SBC) takes it."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import integrate, stats

from brdf_infer._internal import arviz as az
from brdf_infer.model import family
from brdf_infer.model.params import PAPER_CONSTANTS
from brdf_infer.posterior import posterior_bands, tis_band
from tests import independent_bsdf as oracle
from tests.helpers import SUITE_WARMUP, run_cli

SMALL = ["--chains", "2", "--draws", "200", "--warmup", str(SUITE_WARMUP)]


@pytest.fixture(scope="module")
def abg_run(tmp_path_factory):
    """``posterior lya --model abg`` (2 × 200 draws) and its ``--json`` summary."""
    from brdf_infer.cli import main

    out = tmp_path_factory.mktemp("abg_run")
    assert main(["posterior", "lya", "--model", "abg", *SMALL, "--out", str(out)]) == 0
    return out, json.loads((out / "summary.json").read_text())


def _fake_lambertian_run(folder, values: np.ndarray):
    """A run folder of ``lambertian`` written by hand: draws of its one parameter ``tis``."""
    folder.mkdir(parents=True)
    idata = az.from_dict(posterior={"tis": values.reshape(2, -1)})
    idata.posterior.attrs.update(
        {"model": "lambertian", "constants": json.dumps(PAPER_CONSTANTS._asdict())}
    )
    idata.to_netcdf(folder / "posterior.nc")
    (folder / "summary.json").write_text(json.dumps({"scene": "lya"}))
    return folder


def test_a_family_run_summary_names_its_model_parameters_and_units(abg_run):
    out, summary = abg_run
    assert summary["model"] == "abg"
    assert set(summary["median"]) == {"A", "B", "g"}
    assert summary["units"] == {"A": "sr⁻¹", "B": "-", "g": "-"}
    assert summary["pi_brdf0"] is None  # a parameter of Eq. (7) only
    assert set(summary["diagnostics"]["parameters"]) >= {"A", "B", "g"}
    posterior = az.from_netcdf(out / "posterior.nc").posterior
    assert posterior.attrs["model"] == "abg"
    for name in ("A", "B", "g"):
        assert summary["median"][name] == pytest.approx(float(np.median(posterior[name])))
    bands = json.loads((out / "bands.json").read_text())
    at = bands["tis"]["theta_i_deg"].index(70.0)
    assert summary["tis_70deg"]["median"] == bands["tis"]["median"][at]
    assert 0.0 < summary["tis_70deg"]["lo95"] < summary["tis_70deg"]["hi95"] < 1.0


def test_tis_of_a_family_run_is_its_own_quadrature_over_its_draws(abg_run, capsys):
    out, summary = abg_run
    code, text, err = run_cli(
        "tis", "--run", str(out), "--theta-i", "0", "70", "--json", capsys=capsys
    )
    assert code == 0, err
    payload = json.loads(text)
    assert payload["model"] == "abg" and payload["draws"] == 400  # every draw of 2 × 200
    assert payload["median"][1] == pytest.approx(summary["tis_70deg"]["median"], rel=1e-12)
    # one draw's TIS against SciPy's adaptive integral of A / (B + ρ^g) over the hemisphere
    posterior = az.from_netcdf(out / "posterior.nc").posterior
    a, b, g = (float(np.asarray(posterior[n]).reshape(-1)[0]) for n in ("A", "B", "g"))
    theta_i = math.radians(70.0)

    def integrand(phi, theta):
        bx = math.sin(theta) * math.cos(phi) + math.sin(theta_i)
        by = math.sin(theta) * math.sin(phi)
        rho = math.hypot(bx, by)
        return a / (b + rho**g) * math.cos(theta) * math.sin(theta)

    expected, _ = integrate.dblquad(integrand, 0, math.pi / 2, 0, 2 * math.pi, epsrel=1e-10)
    physical = {n: np.asarray(posterior[n]).reshape(-1)[:1] for n in ("A", "B", "g")}
    value = tis_band(family("abg"), physical, [70.0], 1)["median"][0]
    assert value == pytest.approx(expected, rel=1e-7)


def test_readers_written_for_eq7_refuse_a_family_run_naming_its_file(abg_run, capsys):
    """``tis --run --fold`` (no Eq. 10 in ABg) and ``raytrace --run`` (the ray tracer traces
    Eq. 7): one line, exit 2, the run's file named."""
    out, _ = abg_run
    code, text, err = run_cli("tis", "--run", str(out), "--fold", capsys=capsys)
    assert code == 2 and text == "" and "a run of abg has no Eq. (10)" in err
    code, text, err = run_cli("raytrace", "--run", str(out), "--rays", "64", capsys=capsys)
    assert code == 2 and text == "" and len(err.strip().splitlines()) == 1
    assert "a run of abg, not of strumik2024" in err and "posterior.nc" in err


def test_export_of_a_family_run_reads_back_and_its_tis_lines_are_the_band(
    abg_run, tmp_path, capsys
):
    out, _ = abg_run
    target = tmp_path / "bsdf"
    code, text, err = run_cli(
        "export", "--run", str(out), "--out", str(target), "--theta-i", "0", "70",
        "--azimuth-step", "15", "--radial-step", "5", "--draws", "1", "--json", capsys=capsys,
    )  # fmt: skip
    assert code == 0, err
    kinds = {f["kind"] for f in json.loads(text)["files"]}
    assert kinds == {"lower95", "median", "upper95", "tis_q025", "tis_q500", "tis_q975", "draw"}
    code, band, err = run_cli(
        "tis", "--run", str(out), "--theta-i", "0", "70", "--json", capsys=capsys
    )
    band = json.loads(band)
    for kind, key in (("median", "median"), ("upper95", "hi95"), ("lower95", "lo95")):
        read = oracle.read_bsdf(target / f"{kind}.bsdf")
        assert oracle.strictness_problems(target / f"{kind}.bsdf") == []
        np.testing.assert_allclose(read["tis"].reshape(-1), band[key], rtol=1e-6)
        assert any("model: abg" in line for line in read["comments"])
    # the single draw's table is the ABg of that draw at the specular direction (ρ = 0): A / B
    draw = oracle.read_bsdf(target / "draw_000.bsdf")
    posterior = az.from_netcdf(out / "posterior.nc").posterior
    index = int(next(c for c in draw["comments"] if c.startswith("posterior draw")).split()[2])
    a, b = (float(np.asarray(posterior[n]).reshape(-1)[index]) for n in ("A", "B"))
    specular = np.asarray(draw["bsdf"]).reshape(2, draw["scatter_azimuth"].size, -1)[:, :, 0]
    np.testing.assert_allclose(specular, a / b, rtol=1e-6)


def test_abg_rows_of_an_abg_run_are_its_posterior_and_other_families_are_refused(
    abg_run, tmp_path, capsys
):
    out, summary = abg_run
    code, text, err = run_cli(
        "export", "--run", str(out), "--out", str(tmp_path / "abg"), "--format", "abg",
        "--theta-i", "0", "70", "--json", capsys=capsys,
    )  # fmt: skip
    assert code == 0, err
    rows = json.loads(text)["rows"]
    assert [r["theta_i_deg"] for r in rows] == [0.0, 70.0]
    assert rows[1]["A"] == pytest.approx(summary["median"]["A"], rel=1e-9)
    assert rows[1]["tis_model"] == pytest.approx(summary["tis_70deg"]["median"], rel=1e-9)
    lambertian = _fake_lambertian_run(tmp_path / "lam", np.full(20, 0.03))
    target = tmp_path / "refused"
    code, text, err = run_cli(
        "export", "--run", str(lambertian), "--out", str(target), "--format", "abg",
        capsys=capsys,
    )  # fmt: skip
    assert code == 2 and text == "" and "--format" in err and "zemax-bsdf" in err
    assert "Traceback" not in err and not target.exists()


def test_a_lambertian_run_has_the_exact_tis_of_its_draws(tmp_path, capsys):
    values = np.linspace(0.02, 0.04, 40)
    run = _fake_lambertian_run(tmp_path / "lam", values)
    code, text, err = run_cli(
        "tis", "--run", str(run), "--theta-i", "10", "80", "--json", capsys=capsys
    )
    assert code == 0, err
    payload = json.loads(text)
    assert payload["median"] == pytest.approx([np.median(values)] * 2, rel=1e-12)
    assert payload["hi95"] == pytest.approx([np.quantile(values, 0.975)] * 2, rel=1e-12)


def test_posterior_bands_of_a_family_are_quantiles_of_its_brdf_over_draws():
    values = np.linspace(0.01, 0.05, 101)
    bands = posterior_bands(family("lambertian"), {"tis": values}, [30.0])
    brdf = np.asarray(bands["brdf_inplane"]["median"])
    np.testing.assert_allclose(brdf, np.median(values) / np.pi, rtol=1e-12)
    np.testing.assert_allclose(bands["tis"]["lo95"], np.quantile(values, 0.025), rtol=1e-12)
    assert 70.0 in bands["tis"]["theta_i_deg"]


def test_report_of_a_family_run_leads_with_its_result(abg_run, capsys):
    out, _ = abg_run
    code, _, err = run_cli("report", str(out), capsys=capsys)
    assert code == 0, err
    html = (out / "report.html").read_text()
    assert "Result (abg)" in html and "log_knee" in html and "π·BRDF0" not in html
    assert (out / "figures" / "hemisphere.png").is_file()
    assert (out / "figures" / "tis_band.png").is_file()


@pytest.mark.parametrize("command", ["posterior", "run", "sbc"])
def test_unknown_model_option_is_refused_before_any_work(command, tmp_path, capsys):
    target = tmp_path / "x"
    code, out, err = run_cli(
        command, "lya", "--model", "phong", "--out", str(target), capsys=capsys
    )
    assert code == 2 and out == "" and "--model" in err and "phong" in err
    assert not target.exists()


FAMILY_SBC = {"replicates": 6, "draws": 20, "warmup": 100}


def extreme_rank_limit(replicates: int, draws: int, quantities: int, alpha: float = 0.01) -> int:
    """The fewest ranks at 0 or ``draws`` (of ``replicates``) that fail a quantity: under
    calibrated ranks, uniform on 0 … draws, their number is Binomial(replicates, 2/(draws + 1))
    and reaches the limit with probability ≤ alpha/quantities."""
    p = 2 / (draws + 1)
    return next(
        k
        for k in range(replicates + 1)
        if stats.binom.sf(k - 1, replicates, p) <= alpha / quantities
    )


def extreme_quantities(result) -> list[str]:
    """Quantities with too many ranks at an end (:func:`extreme_rank_limit`): the posterior
    sits on one side of the truth, as when it is too narrow or shifted."""
    draws = result.settings.draws
    limit = extreme_rank_limit(result.settings.replicates, draws, len(result.ranks))
    return [
        name
        for name, ranks in result.ranks.items()
        if np.sum((ranks == 0) | (ranks == draws)) >= limit
    ]


def _family_sbc(sigma_scale: float = 1.0):
    from brdf_infer.scene import load_scene
    from brdf_infer.studies.sbc import SbcSettings, run_sbc

    scene = load_scene("lya")
    settings = SbcSettings(**FAMILY_SBC, sigma_scale=sigma_scale)
    return run_sbc(scene, scene.load_measurements(), settings, model="abg")


@pytest.mark.full
def test_sbc_of_another_family_ranks_its_own_parameters():
    """Six replicates cannot test uniformity, but they can see a posterior on one side of
    the truth: four or more of six ranks at 0 or 20 happen with probability 1.0e-3 per
    quantity under calibrated ranks (family-wise < 1 % over the six quantities)."""
    result = _family_sbc()
    assert set(result.quantities) >= {"A", "B", "g", "tis70"}
    assert "brdf0" not in result.quantities
    for ranks in result.ranks.values():
        assert ranks.shape == (6,) and np.all((ranks >= 0) & (ranks <= 20))
    assert extreme_rank_limit(6, 20, len(result.quantities)) == 4
    assert extreme_quantities(result) == [], result.ranks


@pytest.mark.slow  # a second compile of the family's SBC program (≈ 25 s): σ is compiled in
def test_family_sbc_with_a_planted_sigma_fault_fails_the_same_check():
    """The inference's σ three times the simulator's: the learned noise scales shrink to
    absorb it, so their truths rank at the top (measured: repeatability 20 in five of six
    replicates, sample_sd in four). Either scale's ranks flag it: one replicate's NUTS draws
    move on another CPU, and a scale at four of six is at the limit."""
    result = _family_sbc(sigma_scale=3.0)
    assert {"repeatability", "sample_sd"} & set(extreme_quantities(result)), result.ranks


def test_another_familys_run_files_are_the_posterior_records(abg_run):
    from brdf_infer.runs.records import Bands, PosteriorSummary
    from tests.helpers import record_mismatches

    out, summary = abg_run
    assert record_mismatches(summary, PosteriorSummary) == [] and summary["pi_brdf0"] is None
    bands = json.loads((out / "bands.json").read_text())
    assert record_mismatches(bands, Bands) == [] and "draws" in bands["tis"]
