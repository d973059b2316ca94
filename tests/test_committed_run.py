"""The readers of a finished run on the committed small run folder (tests/data/lya_run, written
by tools/make_test_run.py): the fast tier tests ``report``, ``tis --run``, ``export --run`` and
``design`` on it without sampling; the full tier checks that the folder is of the current
format (the fields of a fresh run's files) and asks for the script when it is not."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from brdf_infer._internal import arviz as az
from brdf_infer.cli import main
from tests import independent_bsdf as oracle

COMMITTED = Path(__file__).resolve().parent / "data" / "lya_run"
REGENERATE = "tests/data/lya_run is of an older format: rerun tools/make_test_run.py"


@pytest.fixture
def run(tmp_path) -> Path:
    """A copy of the committed run (the readers add files to the folder they read)."""
    return Path(shutil.copytree(COMMITTED, tmp_path / "run"))


def _json(capsys, *argv: str) -> dict:
    assert main([*argv, "--json"]) == 0, capsys.readouterr().err
    return json.loads(capsys.readouterr().out)


def test_tis_of_the_run_is_its_summary_band(run, capsys):
    """``tis --run`` at 70° gives the band the run recorded (``tis_70deg``)."""
    summary = json.loads((run / "summary.json").read_text())
    band = _json(capsys, "tis", "--run", str(run), "--theta-i", "70")
    recorded = summary["tis_70deg"]
    for key in ("median", "lo95", "hi95"):
        assert band[key][0] == pytest.approx(recorded[key], rel=1e-9)


def test_export_of_the_run_is_ordered_and_read_by_an_independent_reader(run, tmp_path, capsys):
    """The run's median and 95 % tables, read by a reader written apart from the writer: lower
    ≤ median ≤ upper in every cell, and their TIS lines are ``tis --run``'s band."""
    payload = _json(
        capsys, "export", "--run", str(run), "--theta-i", "30", "70",
        "--azimuth-step", "15", "--radial-step", "5", "--out", str(tmp_path / "tables"),
    )  # fmt: skip
    tables = {f["kind"]: oracle.read_bsdf(f["path"]) for f in payload["files"][:3]}
    lower, median, upper = (tables[k]["bsdf"] for k in ("lower95", "median", "upper95"))
    assert np.all(lower <= median) and np.all(median <= upper) and np.any(lower < upper)
    band = _json(capsys, "tis", "--run", str(run), "--theta-i", "30", "70")
    for kind, key in (("lower95", "lo95"), ("median", "median"), ("upper95", "hi95")):
        np.testing.assert_allclose(tables[kind]["tis"][0], band[key], rtol=1e-10)


def test_the_report_of_the_run_shows_its_numbers(run):
    """``report`` writes report.html with the run's elpd ± se, and its figures."""
    assert main(["report", str(run)]) == 0
    summary = json.loads((run / "summary.json").read_text())
    text = (run / "report.html").read_text()
    loo = summary["predictive"]
    assert f"{loo['elpd_loo']:.2f} ± {loo['se']:.2f}" in text
    figures = sorted(p.name for p in (run / "figures").glob("*.png"))
    assert "pareto_k.png" in figures and len(figures) >= 5, figures


def test_design_of_the_run_proposes_a_measurement(run, tmp_path, capsys):
    """``design`` on the run: its current TIS(70°) is the run's band (sd the draws'), and each
    candidate measurement lies on the instrument's geometry and is expected to narrow it
    (sd ratio below 1), best first, as design.json records."""
    out = tmp_path / "design"
    payload = _json(capsys, "design", str(run), "--budget", "1", "--out", str(out))
    summary = json.loads((run / "summary.json").read_text())
    assert payload["target"] == "tis_70deg"
    for key in ("median", "lo95", "hi95"):
        assert payload["current"][key] == pytest.approx(summary["tis_70deg"][key], rel=1e-9)
    ratios = [c["sd_ratio"] for c in payload["candidates"]]
    assert ratios == sorted(ratios) and 0 < ratios[0] < 1
    for candidate in payload["candidates"]:
        assert 0 <= candidate["theta_i_deg"] < 90 and abs(candidate["theta_s_deg"]) < 90
    assert json.loads((out / "design.json").read_text())["candidates"] == payload["candidates"]


def _fields(value, prefix: str = "") -> set[str]:
    """The dotted key paths of a JSON value (list items by their first element's fields)."""
    if isinstance(value, dict):
        return {f"{prefix}{k}" for k in value} | {
            f for k, v in value.items() for f in _fields(v, f"{prefix}{k}.")
        }
    if isinstance(value, list) and value and isinstance(value[0], dict):
        return _fields(value[0], f"{prefix}[].")
    return set()


@pytest.mark.full
def test_the_committed_run_is_of_the_current_format(nuts_run):
    """The committed folder holds the files, summary fields and posterior.nc groups and
    variables a run writes today (the suite's NUTS run of the same scene)."""
    fresh = Path(nuts_run.out)
    ours = {p.name for p in COMMITTED.iterdir()}
    theirs = {p.name for p in fresh.iterdir()} - {"report.html", "figures"}
    assert ours == theirs, REGENERATE
    summary = json.loads((COMMITTED / "summary.json").read_text())
    assert _fields(summary) == _fields(nuts_run.summary), REGENERATE
    committed, written = (
        az.from_netcdf(COMMITTED / "posterior.nc"),
        az.from_netcdf(fresh / "posterior.nc"),
    )
    assert committed.groups() == written.groups(), REGENERATE
    for group in written.groups():
        assert set(committed[group].data_vars) == set(written[group].data_vars), REGENERATE
