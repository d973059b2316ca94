"""The report's figures drawn cheaply (issue 48, item 4): the sampler's chains with matplotlib
directly (same panels and labels as ArviZ's plots), a marginal density of unit area also for a
chain that never moved, and a second process that saves figures exactly as this one would,
or leaves them to this one when it fails."""

from __future__ import annotations

import io
import shutil
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure
from PIL import Image

from brdf_infer._internal import arviz as az
from brdf_infer.report import _chains
from brdf_infer.report._raytrace import figure_png
from brdf_infer.report._saver import FigureSaver

RUN = Path(__file__).parent / "data" / "lya_run"


@pytest.fixture(scope="module")
def idata():
    return az.from_netcdf(RUN / "posterior.nc")


def test_a_density_has_unit_area_and_a_chain_that_never_moved_has_one():
    rng = np.random.default_rng(0)
    for values in (rng.normal(size=1000), rng.exponential(size=1000), np.full(150, 2.5)):
        grid, density = _chains.density(values)
        assert grid.size == density.size == _chains.DENSITY_POINTS
        assert np.all(np.isfinite(density)) and np.all(density >= 0)
        assert np.sum(density) * (grid[1] - grid[0]) == pytest.approx(1.0)


def test_a_density_inside_the_draws_range_is_scipys_gaussian_kde_with_silvermans_bandwidth():
    """Away from the range's ends (where the density reflects and a plain KDE does not) the
    binned, convolved density is scipy's Gaussian KDE with the same bandwidth, to the binning
    error (a bin is 1/512 of the range)."""
    from scipy.stats import gaussian_kde

    values = np.random.default_rng(1).normal(3.0, 0.5, 4000)
    grid, ours = _chains.density(values)
    quartiles = np.percentile(values, [25, 75])
    spread = min(np.std(values), (quartiles[1] - quartiles[0]) / 1.34)
    factor = 0.9 * spread / np.std(values, ddof=1) * values.size**-0.2
    theirs = gaussian_kde(values, bw_method=factor)(grid)
    inside = np.abs(grid - 3.0) < 1.0  # two sd: far from the ends (≈ ±3.5 sd)
    np.testing.assert_allclose(ours[inside], theirs[inside], rtol=0.01)


def test_the_chains_figures_title_every_sampled_coordinate_with_its_units(idata):
    names = _chains.sampled_coordinates(idata)
    labels = _chains.coordinate_labels(idata)
    chains = idata.posterior.sizes["chain"]
    trace = _chains.trace(idata)
    assert [axis.get_title() for axis in trace.axes] == [labels[n] for n in names for _ in "lr"]
    assert all(len(axis.get_lines()) == chains for axis in trace.axes)
    rank = _chains.rank(idata)
    shown = [axis for axis in rank.axes if axis.get_visible()]
    assert [axis.get_title() for axis in shown] == [labels[n] for n in names]
    assert all(len(axis.collections) == chains for axis in shown)
    pair = _chains.pair(idata)
    count = len(names)
    assert len(pair.axes) == count * (count + 1) // 2  # the lower triangle and the diagonal
    short = _chains.coordinate_labels(idata, short=True)
    bottom = [axis.get_xlabel() for axis in pair.axes if axis.get_xlabel()]
    assert sorted(bottom) == sorted(short[n] for n in names)
    assert _chains.coordinate_note(idata) in pair.texts[0].get_text()


def _pixels(png: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(png)))


def _figure(value: float) -> Figure:
    figure = Figure(figsize=(3, 2))
    axis = figure.subplots()
    axis.plot([0, 1], [0, value])
    axis.set_xlabel("x [-]")
    return figure


def test_the_second_process_saves_what_this_one_would():
    with FigureSaver(progress=pytest.fail, second=True) as saver:
        for k in range(5):
            saver.save(f"f{k}", _figure(k + 1.0))
        assert saver._waiting  # some were handed over
        pngs = [saver.png(f"f{k}") for k in range(5)]
    for k, png in enumerate(pngs):
        assert np.array_equal(_pixels(png), _pixels(figure_png(_figure(k + 1.0))))


def test_figures_left_by_a_failed_second_process_are_saved_here():
    said = []
    with FigureSaver(progress=said.append, second=True) as saver:
        saver.save("a", _figure(1.0))  # handed over, while it still imports matplotlib
        saver._process.kill()  # as if it failed
        saver._process.wait()
        saver.save("b", _figure(2.0))  # saved here
        pngs = [saver.png("a"), saver.png("b")]
    for value, png in zip((1.0, 2.0), pngs, strict=True):
        assert np.array_equal(_pixels(png), _pixels(figure_png(_figure(value))))
    assert len(said) == 1 and "failed" in said[0] and said[0].endswith(": a saved here")


def test_the_report_of_the_committed_run_has_every_figure(tmp_path):
    from brdf_infer.report import write_report

    run = tmp_path / "run"
    shutil.copytree(RUN, run)
    write_report(run, progress=lambda message: None)
    for name in ("brdf_bands", "trace", "rank", "pair", "energy", "predictive", "hemisphere"):
        assert (run / "figures" / f"{name}.png").stat().st_size > 5000, name


def test_a_figure_that_does_not_pickle_and_a_missing_interpreter_leave_the_saving_here(
    monkeypatch,
):
    from matplotlib.ticker import FuncFormatter

    odd = _figure(1.0)
    odd.axes[0].xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:.1f}"))
    with FigureSaver(progress=pytest.fail, second=True) as saver:
        saver.save("odd", odd)
        assert saver._waiting == []
        assert _pixels(saver.png("odd")).shape[:2] == (180, 270)
    said = []
    monkeypatch.setattr("sys.executable", "/nonexistent/python")
    with FigureSaver(progress=said.append, second=True) as saver:
        saver.save("a", _figure(1.0))
        assert np.array_equal(_pixels(saver.png("a")), _pixels(figure_png(_figure(1.0))))
    assert len(said) == 1 and "no second process" in said[0]
