"""Plausibility checks and the verdict: copies of the bundled data in percent or in radians stop
every job before any work unless forced; a forced run's one verdict is red, the same on stdout
and in its report; a posterior answer above 1 turns the verdict red by itself."""

from __future__ import annotations

import csv
import dataclasses
import html
import json
import math
import re

import numpy as np
import pytest

from brdf_infer.errors import BadInputError
from brdf_infer.model.params import UV_PAPER, Params
from brdf_infer.report._html import verdict_box
from brdf_infer.scene import load_scene, scene_file
from brdf_infer.verdict import ALL_PASS, FORCED, IMPLAUSIBLE, Verdict, posterior_verdict
from brdf_infer.verdict.plausibility import (
    answer_checks,
    fit_checks,
    measurement_checks,
    require_plausible,
)
from tests.helpers import run_cli

FORCED_NUTS = ["--chains", "2", "--warmup", "500", "--draws", "150"]  # batch's shapes


def bundled_copy(folder, name: str, *, scale=None, radians: bool = False):
    """The bundled scene beside a copy of its CSV (``name``.csv) with the values and their σ
    multiplied by ``scale[series]`` and the angles, with ``radians``, converted to radians."""
    source = scene_file("lya").parent
    with (source / "lya_measurements.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    for row in rows:
        factor = (scale or {}).get(row["series"], 1.0)
        for key in ("reflectance", "reflectance_err"):
            row[key] = repr(factor * float(row[key]))
        if radians:
            for key in ("theta_i_deg", "theta_s_deg"):
                row[key] = repr(math.radians(float(row[key])))
    with (folder / f"{name}.csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    (folder / "lya_tis_reference.csv").write_text((source / "lya_tis_reference.csv").read_text())
    text = (source / "lya.scene.toml").read_text()
    scene = folder / f"{name}.toml"
    scene.write_text(text.replace('"lya_measurements.csv"', f'"{name}.csv"'))
    return scene


PERCENT = {"I": 100.0, "II": 100.0}


@pytest.mark.parametrize(
    "argv",
    [
        ["run", "--out", "{out}"],
        ["posterior", "--out", "{out}"],
        ["batch", "--out", "{out}"],
        ["compare", "--models", "abg", "lambertian", "--out", "{out}"],
        ["fit"],
        ["fit", "--method", "lsq", "--model", "abg"],
    ],
    ids=["run", "posterior", "batch", "compare", "fit", "fit-abg"],
)
def test_values_in_percent_stop_every_job_before_any_work(tmp_path, capsys, argv):
    scene = bundled_copy(tmp_path, "percent", scale=PERCENT)
    out = tmp_path / "out"
    command, *options = argv
    options = [option.format(out=out) for option in options]
    code, stdout, err = run_cli(command, str(scene), *options, capsys=capsys)
    # a batch names each scene it skips on its way, then fails as every other command does
    assert code == 2 and stdout == "" and err.count("\n") == (2 if command == "batch" else 1), err
    err = err.splitlines()[-1]
    assert err.startswith("brdf-infer: error: ")
    assert "percent.csv" in err and "field 'reflectance'" in err and "series I, II" in err
    assert "look like percent" in err and "--force" in err and "Traceback" not in err
    assert not out.exists()


def test_angles_in_radians_stop_run_before_any_work(tmp_path, capsys):
    scene = bundled_copy(tmp_path, "radians", radians=True)
    out = tmp_path / "out"
    code, stdout, err = run_cli("run", str(scene), "--out", str(out), capsys=capsys)
    assert code == 2 and stdout == "" and err.count("\n") == 1, err
    assert "radians.csv" in err and "field 'theta_i_deg/theta_s_deg'" in err
    assert "look like radians" in err and "largest 1.4" in err and "--force" in err
    assert not out.exists()


def test_a_fit_that_scatters_more_than_it_receives_stops_run_before_sampling(tmp_path, capsys):
    """Values 20 and 13 times too large pass the row check (the dimmest row of each series
    stays below π·BRDF = 1: 0.96 and 0.94), but the paper fit's TIS(80°) is 1.1."""
    scene = bundled_copy(tmp_path, "bright", scale={"I": 20.0, "II": 13.0})
    loaded = load_scene(scene)
    assert measurement_checks(loaded, loaded.load_measurements()) == []
    out = tmp_path / "out"
    code, stdout, err = run_cli("run", str(scene), "--out", str(out), capsys=capsys)
    assert code == 2 and stdout == "", err
    assert err.splitlines()[-1].startswith("brdf-infer: error: ")
    assert "the paper fit scatters more light than it receives: TIS up to 1.1" in err
    assert "at θi = 80 deg" in err and "bright.csv" in err and "--force" in err
    assert not out.exists()


@pytest.mark.full
@pytest.mark.usefixtures("width_refit_off")  # every variant's k̂ > 0.7: three new samplers
def test_a_forced_percent_run_has_one_red_verdict_on_stdout_and_in_its_report(tmp_path, capsys):
    scene = bundled_copy(tmp_path, "percent", scale=PERCENT)
    out = tmp_path / "out"
    argv = ["posterior", str(scene), *FORCED_NUTS, "--out", str(out), "--force"]
    code, stdout, err = run_cli(*argv, capsys=capsys)
    assert code == 0, err
    assert "warning: forced past a plausibility check: " in err
    verdicts = [line for line in stdout.splitlines() if line.startswith("verdict")]
    assert len(verdicts) == 1 and "diagnostics:" not in stdout
    text = verdicts[0].removeprefix("verdict: ")
    recorded = json.loads((out / "summary.json").read_text())["verdict"]
    lines = recorded["lines"]
    assert Verdict.from_json(recorded).text == text
    assert lines[0].startswith(FORCED) and "look like percent" in lines[0]
    # the physical prior (no coating with TIS > 1) cannot follow data 100 times too bright:
    # the chains fail, and the verdict says so (an implausible median is no longer possible
    # for Eq. 7; test_the_verdict_passes_a_plausible_run_and_names_each_failure_in_order keeps the
    # check for other families)
    # (which diagnostic fails, and whether a row's k̂ is high, is the chance of the chains: any
    # sampler failure will do; a high-k̂ row, where there is one, comes last and names the rows)
    assert any(line.startswith(("R-hat", "bulk ESS", "tail ESS")) or "divergent" in line
               for line in lines)  # fmt: skip
    if recorded_summary(out)["predictive"]["pareto_k_high"]:
        assert re.search(r"Pareto k > 0\.\d+ ", lines[-1])
    # the report renders the recorded verdict as it stands (``report`` itself: tests/test_cli.py
    # and tests/test_report.py, whose runs write theirs)
    box = verdict_box(Verdict.from_json(json.loads((out / "summary.json").read_text())["verdict"]))
    assert box.startswith(
        f'<div class="verdict fail"><strong>Verdict: {html.escape(text)}</strong>'
    )


def test_a_forced_fit_states_what_it_went_past(tmp_path, capsys):
    scene = bundled_copy(tmp_path, "percent", scale=PERCENT)
    code, stdout, err = run_cli("fit", str(scene), "--force", "--json", capsys=capsys)
    assert code == 0, err
    rows, fit = json.loads(stdout)["implausible"]
    assert "look like percent" in rows
    assert "the paper fit scatters more light than it receives: π·BRDF0 = 3.6" in fit
    assert err.count("warning: forced past a plausibility check: ") == 2


def _summary(pi_brdf0: float, failures=(), pareto_k_high: int = 0) -> dict:
    return {
        "diagnostics": {"failures": list(failures)},
        "predictive": {"pareto_k_high": pareto_k_high},
        "pi_brdf0": {"median": pi_brdf0, "lo95": pi_brdf0 / 2, "hi95": 2 * pi_brdf0},
    }


def _tis_band(at_89: float) -> dict:
    """A TIS median rising linearly from 0.04 at 0° to ``at_89`` at 89°."""
    grid = np.arange(0.0, 90.0)
    return {"tis": {"theta_i_deg": grid.tolist(), "median": np.linspace(0.04, at_89, 90).tolist()}}


def test_the_verdict_passes_a_plausible_run_and_names_each_failure_in_order():
    angles = (18.0, 45.0, 80.0)
    verdict = posterior_verdict(_summary(0.036), _tis_band(0.1), angles)
    assert verdict.ok and verdict.lines == () and verdict.text == ALL_PASS
    assert verdict.as_json() == {
        "ok": True,
        "lines": [],
        "facts": [],
        "text": "every diagnostic passes",
    }
    # TIS(80°) = 0.04 + 80/89 · (1.2 − 0.04) = 1.083 > 1; 45° stays below (0.63)
    verdict = posterior_verdict(
        _summary(1.2, ["R-hat 1.040 > 1.01"], pareto_k_high=2),
        _tis_band(1.2),
        angles,
        forced=["rows.csv, field 'reflectance': planted"],
    )
    assert not verdict.ok
    forced, answer, sampler, pareto = verdict.lines
    assert forced == FORCED + "rows.csv, field 'reflectance': planted"
    assert answer.startswith(IMPLAUSIBLE)
    assert "π·BRDF0 = 1.2 and TIS up to 1.08 at θi = 80 deg, above 1" in answer
    assert sampler == "R-hat 1.040 > 1.01"
    assert pareto.startswith("2 measurement(s) with Pareto k > 0.7")
    assert verdict.text == "; ".join(verdict.lines)
    # a thinned table's PSIS-LOO is judged at its own draws' limit, which the words name
    thinned = _summary(0.1, [], pareto_k_high=1)
    thinned["predictive"]["pareto_k_limit"] = 2 / 3
    assert posterior_verdict(thinned, _tis_band(0.1), angles).lines == (
        "1 measurement(s) with Pareto k > 0.667 (PSIS-LOO unreliable there)",
    )
    # a family without BRDF0 is judged by its TIS alone
    family_run = {**_summary(0.0), "pi_brdf0": None}
    assert posterior_verdict(family_run, _tis_band(0.5), angles).ok
    assert not posterior_verdict(family_run, _tis_band(3.0), angles).ok


def test_row_checks_read_degrees_and_fractions(lya):
    scene, rows = lya
    assert measurement_checks(scene, rows) == []  # dimmest rows: π·BRDF 0.048 (I), 0.073 (II)
    # 14 times too bright: series II's dimmest row crosses 1 (1.02), series I's not (0.67)
    brighter = dataclasses.replace(rows, reflectance=14.0 * rows.reflectance)
    (found,) = measurement_checks(scene, brighter)
    assert "every row of series II implies π·BRDF > 1" in found.problem and "1.02" in found.problem
    assert found.field == "reflectance" and found.file == str(rows.path)
    # one distinct non-zero angle cannot tell degrees from radians; two can
    single = dataclasses.replace(
        rows, theta_i_deg=np.zeros(len(rows)), theta_s_deg=np.full(len(rows), 1.2)
    )
    assert not any("radians" in f.problem for f in measurement_checks(scene, single))
    radians = dataclasses.replace(
        rows, theta_i_deg=np.radians(rows.theta_i_deg), theta_s_deg=np.radians(rows.theta_s_deg)
    )
    assert any("look like radians" in f.problem for f in measurement_checks(scene, radians))


def test_answer_checks_and_the_refusal(lya):
    scene, rows = lya
    assert fit_checks(scene, rows, UV_PAPER, "the paper's parameters") == []
    assert answer_checks("x", [10.0, 70.0], [0.04, 0.06], math.pi * UV_PAPER.brdf0) == []
    bright = Params(0.5, 0.0, 0.0, 0.0, 4.5, -12.0)  # π·BRDF0 = 1.57, TIS(10°) ≈ 1.57
    (found,) = fit_checks(scene, rows, bright, "a bright fit")
    assert "π·BRDF0 = 1.57 and TIS up to" in found.problem and found.field == "reflectance"
    with pytest.raises(BadInputError, match=r"a bright fit scatters.*--force") as error:
        require_plausible([found], force=False)
    assert error.value.file == str(rows.path) and error.value.field == "reflectance"
    require_plausible([found], force=True)  # insisting goes on


def recorded_summary(out):
    """The run's summary.json."""
    return json.loads((out / "summary.json").read_text())
