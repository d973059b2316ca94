"""Tables as a scatterometer writes them (issue 35, items 3 and 4): a .BSDF table's zero cells
and dropouts are counted by stated rules and named in the verdict; in-plane figures show
in-plane rows, out-of-plane rows have a residual map; every measured incidence angle gets its
band, in a layout that stays legible at 18 angles."""

from __future__ import annotations

import dataclasses
import json
from types import SimpleNamespace

import matplotlib.pyplot as plt
import numpy as np
import pytest

from brdf_infer.scene import load_scene
from brdf_infer.tables.bsdf_file import specular_frame_to_model
from brdf_infer.tables.screening import dropout_mask, table_facts
from brdf_infer.verdict import answer_facts
from tests import vendor_table as vendor


@pytest.fixture(scope="module")
def tables(tmp_path_factory):
    """The vendor table's scene with its planted dropout, and without."""
    scenes = {}
    for planted in (True, False):
        folder = tmp_path_factory.mktemp(f"vendor_{planted}")
        scenes[planted] = load_scene(vendor.write_vendor_scene(folder, dropout=planted))
    return {planted: (scene, scene.load_measurements()) for planted, scene in scenes.items()}


def _direction(aoi: int, azimuth: int, radial: int) -> tuple[float, float, float]:
    """(θi, θ, φ) [deg] of a cell of the vendor table."""
    theta_i = vendor.AOI_DEG[aoi]
    theta, phi, _ = specular_frame_to_model(
        theta_i, vendor.AZIMUTH_DEG[azimuth], vendor.RADIAL_DEG[radial]
    )
    return theta_i, float(theta), float(phi)


@pytest.mark.full
def test_a_planted_dropout_is_flagged_named_and_left_out(tables):
    rows = tables[True][1]
    screening = rows.screening
    assert len(screening.dropouts) == 1
    (dropout,) = screening.dropouts
    theta_i, theta, phi = _direction(*vendor.DROPOUT_CELL)
    assert dropout["theta_i_deg"] == theta_i
    assert dropout["theta_s_deg"] == pytest.approx(theta)
    assert dropout["phi_s_deg"] == pytest.approx(phi)
    assert dropout["neighbours"] > 3.0 * dropout["value"]
    here = (rows.theta_i_deg == theta_i) & np.isclose(rows.theta_s_deg, theta)
    assert not np.any(here & np.isclose(np.nan_to_num(rows.phi_s_deg), phi))
    assert len(tables[False][1]) == len(rows) + 1  # the one row it left out


@pytest.mark.full
def test_an_unplanted_table_flags_no_dropout(tables):
    """The same table without its dropout, and noise-free or noisier versions of it (5–20 %
    log-normal, other seeds): no cell is flagged."""
    assert tables[False][1].screening.dropouts == ()
    grid_azimuth, grid_radial = np.meshgrid(vendor.AZIMUTH_DEG, vendor.RADIAL_DEG, indexing="ij")
    for seed in range(6):
        table = vendor.vendor_table(dropout=False, seed=seed)
        noise = np.random.default_rng(seed).normal(0.0, 0.1 * (seed % 3), table.bsdf.shape)
        for aoi, block in zip(vendor.AOI_DEG, table.bsdf[0] * np.exp(noise[0]), strict=True):
            theta, _, z = (
                np.asarray(a) for a in specular_frame_to_model(aoi, grid_azimuth, grid_radial)
            )
            assert not dropout_mask(block, (z > 0.0) & (theta < 90.0)).any(), (seed, aoi)


def test_the_dropout_rule_spares_slopes_and_table_edges():
    """A steep ramp (a factor 10 per step) and a cell with two neighbours are no dropouts; a
    cell a tenth of a flat field is."""
    ramp = np.tile(10.0 ** -np.arange(8.0), (5, 1))
    above = np.ones(ramp.shape, bool)
    assert not dropout_mask(ramp, above).any()
    field = np.full((5, 8), 3.6e-2) * np.exp(np.random.default_rng(1).normal(0, 0.05, (5, 8)))
    field[2, 4] = 3.5e-3
    field[0, 0] = 3.5e-3  # a corner: two neighbours, not judged
    flagged = dropout_mask(field, above)
    assert flagged[2, 4] and flagged.sum() == 1


@pytest.mark.full
def test_zero_cells_are_counted_once_with_the_detection_limit(tables):
    rows = tables[True][1]
    above = [cell for cell in vendor.ZERO_CELLS if _direction(*cell)[1] < 90.0]
    assert rows.screening.zero_cells == len(above) > 0
    assert rows.screening.zero_directions.shape == (len(above), 3)
    assert rows.screening.detection_limit == pytest.approx(rows.reflectance.min())
    assert np.all(rows.reflectance > 0.0)


def test_the_verdict_names_each_rule_and_count_and_a_csv_says_nothing_new(tables, lya):
    record = tables[True][1].screening.as_json()
    facts = table_facts(record)
    assert facts[0].startswith(f"{record['zero_cells']} zero cell(s)")
    assert facts[1].startswith("1 dropout(s)") and "θi 30°" in facts[1]
    assert answer_facts({"table": record})[:2] == facts
    assert json.loads(json.dumps(record)) == record  # as summary.json holds it
    clean = {**record, "zero_cells": 0, "dropouts": []}
    assert table_facts(clean) == [] and table_facts(None) == []
    assert lya[1].screening is None  # a CSV: no "table" record, no new fact
    assert answer_facts({}) == []


def test_every_measured_incidence_angle_gets_a_band(tables):
    scene, rows = tables[True]
    angles = np.linspace(0.0, 85.0, 18)
    many = dataclasses.replace(rows, theta_i_deg=angles[np.arange(len(rows)) % 18])
    assert scene.band_theta_i_deg(many) == tuple(angles)
    assert scene.band_theta_i_deg(rows) == vendor.AOI_DEG


def _band(angles) -> dict:
    theta_s = list(np.arange(-90.0, 90.5, 5.0))
    values = [[0.01] * len(theta_s) for _ in angles]
    return {
        "theta_i_deg": list(angles),
        "theta_s_deg": theta_s,
        **{k: values for k in ("median", "lo68", "hi68", "lo95", "hi95")},
    }


@pytest.mark.full
def test_the_in_plane_figure_shows_in_plane_rows_only(tables):
    from brdf_infer.report._figures import brdf_bands

    scene, rows = tables[True]
    figure = brdf_bands({"brdf_inplane": _band(vendor.AOI_DEG)}, scene, rows)
    for axis, angle in zip(figure.axes, vendor.AOI_DEG, strict=False):
        (data,) = [line for line in axis.get_lines() if line.get_label() == "in-plane data"]
        in_plane = (rows.theta_i_deg == angle) & ~rows.out_of_plane
        assert len(data.get_xdata()) == in_plane.sum() > 0
    assert rows.out_of_plane.sum() > 0
    plt.close(figure)


def test_eighteen_angles_are_small_multiples_with_the_legend_outside(tables):
    from brdf_infer.report._figures import brdf_bands

    scene, rows = tables[True]
    angles = np.linspace(0.0, 85.0, 18)
    figure = brdf_bands({"brdf_inplane": _band(angles)}, scene, rows)
    shown = [axis for axis in figure.axes if axis.get_visible()]
    assert [axis.get_title() for axis in shown] == [f"θi = {a:g}°" for a in angles]
    assert len({axis.get_position().x0 for axis in shown}) == 4  # four columns, five lines
    assert figure.legends and all(axis.get_legend() is None for axis in shown)
    plt.close(figure)


def test_the_residual_map_has_a_panel_per_angle_and_marks_what_was_left_out(tables):
    from brdf_infer.report._table_views import residual_hemisphere, table_section

    rows = tables[True][1]
    observed = np.log(rows.reflectance)
    idata = SimpleNamespace(
        observed_data={"obs": observed},
        posterior_predictive={
            "obs": observed + np.random.default_rng(0).normal(0, 0.05, (2, 9, 1))
        },
    )
    record = rows.screening.as_json()
    figure = residual_hemisphere(idata, rows, record)
    panels = [axis for axis in figure.axes if axis.name == "polar" and axis.get_visible()]
    assert [axis.get_title() for axis in panels] == [f"θi = {a:g}°" for a in vendor.AOI_DEG]
    crosses = [line for axis in panels for line in axis.get_lines() if line.get_marker() == "x"]
    assert sum(len(line.get_xdata()) for line in crosses) == 1
    plt.close(figure)
    html = "".join(table_section({"table": record}))
    assert "Dropouts: θi 30°" in html and "left out" in html
    assert table_section({}) == []


@pytest.mark.slow  # a NUTS run of its own program (≈ 1–2 min on two cores)
def test_a_run_of_the_vendor_table_records_names_and_shows_what_it_left_out(tables, tmp_path):
    from brdf_infer.posterior import run_posterior
    from brdf_infer.report import write_report
    from brdf_infer.runs.records import PosteriorSummary
    from tests.helpers import record_mismatches

    scene, rows = tables[True]
    run = run_posterior(
        scene, rows, chains=2, warmup=150, draws=150, out=tmp_path, progress=False, refit=False
    )
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert record_mismatches(summary, PosteriorSummary) == []
    assert summary["table"]["zero_cells"] == rows.screening.zero_cells
    assert len(summary["table"]["dropouts"]) == 1
    assert summary["verdict"]["facts"][:2] == table_facts(summary["table"])
    assert [f"tis_{a:g}deg" in summary["width"] for a in vendor.AOI_DEG] == [True] * 4
    _, verdict = write_report(run.out, progress=lambda message: None)
    text = (tmp_path / "report.html").read_text()
    assert "What reading the table left out" in text and verdict.facts[0] in text
    assert (tmp_path / "figures" / "residual_map.png").is_file()
