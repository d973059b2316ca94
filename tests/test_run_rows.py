"""A run folder is self-contained: it keeps the rows it sampled (``posterior.nc`` group
``measurements``, :func:`brdf_infer.posterior.run_measurements`), so its readers — report,
design, ``tis --run``, ``export --run`` — read no measurement file, and work after it is
moved or deleted."""

from __future__ import annotations

import shutil

import numpy as np

from brdf_infer._internal import arviz as az
from brdf_infer.posterior import run_measurements
from brdf_infer.posterior._results import store_measurements
from brdf_infer.scene._records import Scene
from brdf_infer.tables.measurements import Measurements
from brdf_infer.tables.screening import TableScreening
from tests.helpers import assert_allclose


def _same_rows(left: Measurements, right: Measurements) -> None:
    for name in ("series", "sample"):
        assert np.asarray(getattr(left, name)).tolist() == np.asarray(getattr(right, name)).tolist()
    for name in ("theta_i_deg", "theta_s_deg", "reflectance", "reflectance_err", "phi_s_deg"):
        a, b = getattr(left, name), getattr(right, name)
        assert (a is None) == (b is None), name
        if a is not None:
            assert_allclose(np.asarray(a, float), np.asarray(b, float), rtol=0, atol=0)
    assert left.quantity == right.quantity


def test_the_rows_round_trip_through_posterior_nc(tmp_path):
    """Every column (a σ column, out-of-plane azimuths with NaN in the plane), the quantity
    and what reading a .BSDF table left out (counts, dropouts, zero directions) come back
    exactly from a written and re-read ``posterior.nc``."""
    rows = Measurements(
        path=tmp_path / "rows.bsdf",
        series=np.array(["BSDF", "BSDF", "BSDF"]),
        sample=np.array(["a", "a", "b"]),
        theta_i_deg=np.array([10.0, 45.0, 70.0]),
        theta_s_deg=np.array([5.0, -30.0, 60.0]),
        reflectance=np.array([0.01, 0.02, 1.5]),
        reflectance_err=np.array([0.001, 0.002, 0.1]),
        quantity="brdf",
        phi_s_deg=np.array([np.nan, 30.0, np.nan]),
        screening=TableScreening(
            zero_cells=2,
            detection_limit=1e-5,
            below_horizon=1,
            dropouts=(
                {
                    "theta_i_deg": 10.0,
                    "theta_s_deg": 3.0,
                    "value": 1e-6,
                    "neighbours": 1e-3,
                },
            ),
            zero_directions=np.array([[10.0, 80.0, 90.0], [45.0, 85.0, 180.0]]),
        ),
    )
    idata = az.from_dict(posterior={"x": np.zeros((1, 4))})
    store_measurements(idata, rows)
    idata.to_netcdf(tmp_path / "posterior.nc")
    back = run_measurements(az.from_netcdf(tmp_path / "posterior.nc"))
    _same_rows(back, rows)
    assert back.screening.zero_cells == 2 and back.screening.below_horizon == 1
    assert back.screening.dropouts == rows.screening.dropouts
    assert_allclose(back.screening.zero_directions, rows.screening.zero_directions)
    assert run_measurements(az.from_dict(posterior={"x": np.zeros((1, 4))})) is None  # older


def test_the_readers_of_a_run_read_no_measurement_file(nuts_run, tmp_path, monkeypatch, capsys):
    """With every read of a scene's measurement file made to fail (as when the file was
    moved), a copy of a run gives its report, its design and ``tis --run`` (``export --run``
    reads the posterior draws alone, as ``tis --run`` does); the rows kept are the run's."""
    from brdf_infer.cli import main

    run = tmp_path / "run"
    shutil.copytree(nuts_run.out, run)

    def moved(self):
        raise AssertionError(f"read {self.measurements_path}")

    monkeypatch.setattr(Scene, "load_measurements", moved)
    stored = run_measurements(az.from_netcdf(run / "posterior.nc"))
    assert len(stored) == nuts_run.summary["n_points"]
    for argv in (
        ["report", str(run)],
        ["design", str(run), "--budget", "1", "--out", str(tmp_path / "design")],
        ["tis", "--run", str(run)],
    ):
        assert main(argv) == 0, (argv, capsys.readouterr().err)
