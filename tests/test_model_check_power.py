"""The model-check power benchmark (benchmarks._model_check_power): its simulator keeps
the bundled rows' layout and plants each fault where it should (the noise-free part: uv-paper's
prediction, series II alone moved by ln 1.3, a θs trend of ln 1.4 end to end), replicate i of
every fault shares its noise, and the section formats its table from given rows."""

import math

import numpy as np
import pytest

from benchmarks._model_check_power import (
    FAULTS,
    alpha_fault_truth,
    median_text,
    model_check_power,
    power_section,
    share_cell,
    simulate,
)
from brdf_infer.model.params import UV_PAPER
from brdf_infer.studies.synthetic import synthetic_measurements

NONE = FAULTS[0]
ALPHA = FAULTS[1]
SHAPE_15 = FAULTS[2]
SERIES = FAULTS[4]
TREND = FAULTS[5]


def _log(data) -> np.ndarray:
    return np.log(np.asarray(data.reflectance, float))


def test_the_faults_are_those_of_the_issue():
    assert NONE.size == "—" and NONE.scatter == 0.0 and NONE.shift is None
    assert ALPHA.scene == "lya-fixed" and ALPHA.truth == "alpha-low"
    assert [f.scatter for f in FAULTS if f.scatter] == [0.15, 0.28]
    assert (SERIES.shift, TREND.shift) == ("series_II", "theta_s")
    truth = alpha_fault_truth()
    assert truth.alpha == 3.6 and truth.theta_s0 == UV_PAPER.theta_s0
    # the prior's coordinates b2 = a2·90^(1+α), b3 = a3·90^(2+α) kept
    assert truth.a2 * 90 ** (1 + 3.6) == pytest.approx(UV_PAPER.a2 * 90 ** (1 + 4.5), rel=1e-12)
    assert truth.a3 * 90 ** (2 + 3.6) == pytest.approx(UV_PAPER.a3 * 90 ** (2 + 4.5), rel=1e-12)


def test_simulated_rows_have_the_bundled_geometry(lya):
    scene, rows = lya
    data = simulate(scene, rows, NONE, np.random.default_rng(0))
    assert len(data) == len(rows) == 42
    for field in ("series", "sample", "theta_i_deg", "theta_s_deg"):
        assert np.array_equal(np.asarray(getattr(data, field)), np.asarray(getattr(rows, field)))
    assert np.all(data.reflectance > 0)
    # each row keeps its relative ±
    assert data.reflectance_err / data.reflectance == pytest.approx(
        rows.reflectance_err / rows.reflectance, rel=1e-12
    )
    # noise of the error model's size: within a factor 3 of uv-paper's prediction
    clean = _log(synthetic_measurements(scene, rows, UV_PAPER))
    assert np.max(np.abs(_log(data) - clean)) < math.log(3.0)


def test_the_noise_free_part_is_the_truths_prediction_with_the_fault(lya):
    scene, rows = lya
    rng = np.random.default_rng(1)
    quiet = {f: _log(simulate(scene, rows, f, rng, noise=False)) for f in FAULTS}
    paper = _log(synthetic_measurements(scene, rows, UV_PAPER))
    assert quiet[NONE] == pytest.approx(paper, abs=1e-12)
    assert quiet[SHAPE_15] == pytest.approx(paper, abs=1e-12)  # its scatter is random
    low = _log(synthetic_measurements(scene, rows, alpha_fault_truth()))
    assert quiet[ALPHA] == pytest.approx(low, abs=1e-12)
    assert np.max(np.abs(low - paper)) > 0.05
    moved = quiet[SERIES] - paper
    second = np.asarray(rows.series) == "II"
    assert moved[second] == pytest.approx(np.full(second.sum(), math.log(1.3)), abs=1e-12)
    assert moved[~second] == pytest.approx(np.zeros((~second).sum()), abs=1e-12)
    trend = quiet[TREND] - paper
    theta_s = np.asarray(rows.theta_s_deg, float)
    assert trend[np.argmax(theta_s)] - trend[np.argmin(theta_s)] == pytest.approx(math.log(1.4))
    assert np.mean(trend) == pytest.approx(0.0, abs=1e-12)
    assert np.ptp(np.polyfit(theta_s, trend, 1)[0] * theta_s - trend) < 1e-12  # linear in θs


def test_a_replicate_shares_its_noise_across_faults_and_the_shape_error_has_its_rms(lya):
    """Replicate i draws the same noise for every fault (the fault's scatter last): the series
    fault is the unfaulted data times 1.3 on series II exactly, and the shape error's ln ratio
    to them has sd 0.15 (840 rows of 20 replicates: within 4 standard errors, ± 0.015)."""
    scene, rows = lya
    second = np.asarray(rows.series) == "II"
    ratios = []
    for replicate in range(20):
        base = _log(simulate(scene, rows, NONE, np.random.default_rng([3, replicate])))
        series = _log(simulate(scene, rows, SERIES, np.random.default_rng([3, replicate])))
        assert series - base == pytest.approx(np.where(second, math.log(1.3), 0.0), abs=1e-12)
        shape = _log(simulate(scene, rows, SHAPE_15, np.random.default_rng([3, replicate])))
        ratios.append(shape - base)
    ratios = np.concatenate(ratios)
    assert abs(np.sqrt(np.mean(ratios**2)) - 0.15) < 4 * 0.15 / math.sqrt(2 * ratios.size)


def test_median_text_takes_each_numbers_median():
    texts = ["θs 24 %, θi 22 %", "θs 10 %, θi 30 %", "θs 30 %, θi 2.4e+04 %"]
    assert median_text(texts) == "θs 24 %, θi 30 %"
    assert median_text(["a", "b", "b"]) == "b" and median_text([]) == "—"


def test_power_section_formats_a_table_from_given_rows():
    def row(fault, size, failed, any_failed, detectable):
        judged = dict.fromkeys(["fit_repeatability", "loo_pit", "at_bound"], 30)
        return {
            "fault": fault,
            "size": size,
            "replicates": 30,
            "failed": failed,
            "judged": judged,
            "any": any_failed,
            "p": {},
            "detectable": detectable,
            "divergent": 1,
            "seconds": 10.0,
        }

    clean = {"loo_pit": ["rows scattering 20 times", "rows scattering 30 times"]}
    rows = [
        row("none", "—", {"loo_pit": 0}, 0, clean),
        row("θs trend", "× 1.4", {"fit_repeatability": 10, "loo_pit": 3}, 12, {}),
    ]
    lines = power_section(rows)
    assert lines[0] == "## Model check: power" and lines[1] == ""
    text = "\n".join(lines)
    table = next(line for line in text.splitlines() if line.startswith("| fault"))
    header = [cell.strip() for cell in table.strip("|").split("|")]
    assert header == [
        "fault",
        "size",
        "replicates",
        "`fit_repeatability`",
        "`loo_pit`",
        "`at_bound`",
        "any check",
    ]
    assert "| none | — | 30 | 0 ± 0 % | 0 ± 0 % | 0 ± 0 % | 0 ± 0 % |" in text
    assert "| θs trend | × 1.4 | 30 | 33 ± 9 % | 10 ± 5 % | 0 ± 0 % | 40 ± 9 % |" in text
    assert "`loo_pit`: rows scattering 25 times" in text
    assert "divergent transition: 2 of 60" in text
    assert share_cell(1, 30) == "3 ± 3 %" and share_cell(0, 0) == "—"


@pytest.mark.slow
def test_one_replicate_of_every_fault_runs_every_check():
    """One replicate a fault (two NUTS programs compiled, a few minutes): every row has the
    least-squares and posterior checks, each judged once."""
    rows = model_check_power(replicates=1, seed=5, progress=None)
    assert [(r["fault"], r["size"]) for r in rows] == [(f.name, f.size) for f in FAULTS]
    for row in rows:
        assert {"fit_residual_trend", "loo_pit", "residual_trend", "at_bound"} <= set(row["judged"])
        assert all(count == 1 for count in row["judged"].values())
        assert 0 <= row["any"] <= 1
    assert power_section(rows)[0] == "## Model check: power"
