"""The numbers the docs quote from a run agree with a run.

- Posterior quantities of the bundled run (``brdf-infer run lya``, default settings) are
  checked against the suite's shared run of the same scene (``nuts_run``: 4 chains, 2000
  draws, a shorter warmup) within Monte Carlo error: two runs of one posterior differ by
  chance, not by a bug (see :func:`monte_carlo_tolerance`).
- Wall times cannot be checked by rerunning them: the docs quote the speed benchmark's report
  (``reports/benchmarks-speed.md``, written by ``brdf-infer bench --speed``), rounded to the
  second, and each quote must equal the report's number.
"""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from scipy import stats

from tests.helpers import REPO

# Quotes of the bundled run: (file, the text as the docs print it [%], quantity, the numbers it
# holds). Quantities: a key of summary.json ("tis_70deg", "pi_brdf0"), "tis_85deg" (bands.json)
# or "tis_70deg_fold" / "tis_85deg_fold" (`brdf-infer tis --run DIR --fold`).
BUNDLED_RUN_QUOTES = [
    ("docs/paper.md", "| 6.65 (95 %: 5.40–8.48) |", "tis_70deg", "median lo95 hi95"),
    ("docs/paper.md", "| 8.82 (6.77–12.13) |", "tis_85deg", "median lo95 hi95"),
    ("docs/paper.md", "| 6.55 (5.35–8.34) |", "tis_70deg_fold", "median lo95 hi95"),
    ("docs/paper.md", "| 8.45 (6.54–11.49) |", "tis_85deg_fold", "median lo95 hi95"),
    ("docs/posterior.md", "TIS(70°) =\n6.65 % (95 %: 5.40–8.48 %", "tis_70deg", "median lo95 hi95"),
    ("docs/posterior.md", "π·BRDF0 = 4.05 % (3.59–4.57 %)", "pi_brdf0", "median lo95 hi95"),
    ("docs/instruments.md", "| 6.65 % (5.40–8.48 %) |", "tis_70deg", "median lo95 hi95"),
    ("docs/instruments.md", "| 4.05 % (3.59–4.57 %) |", "pi_brdf0", "median lo95 hi95"),
    ("docs/instruments.md", "1.29 × 10⁻² (1.14–1.45 × 10⁻²)", "brdf0", "median lo95 hi95"),
    ("docs/instruments.md", "TIS(70°) 6.65 % (5.40–8.48 %)", "tis_70deg", "median lo95 hi95"),
    ("docs/error-model.md", "| TIS(70°) 5.40–8.48 % without", "tis_70deg", "lo95 hi95"),
    ("docs/error-model.md", "| π·BRDF0 3.59–4.57 % without", "pi_brdf0", "lo95 hi95"),
    # which coating (docs/posterior.md, "Which coating"): a new part, the samples measured, τ
    (
        "docs/posterior.md",
        "a new part's is\n6.65 % (5.36–8.60 %)",
        "new_part_tis_70deg",
        "median lo95 hi95",
    ),
    (
        "docs/posterior.md",
        "on average,\n6.65 % (5.43–8.47 %)",
        "measured_tis_70deg",
        "median lo95 hi95",
    ),
    ("docs/posterior.md", "τ learned: 3.0 %, 95 %\n0.19–9.2 %", "sample_sd", "median lo95 hi95"),
    # the sensitivity study's default posterior (4 × 500 draws)
    ("docs/error-model.md", "| **6.69 (5.44–8.52)** |", "tis_70deg", "median lo95 hi95"),
    ("docs/error-model.md", "| **4.04 (3.62–4.55)** |", "pi_brdf0", "median lo95 hi95"),
]
# Quotes of the bundled run's width record (file, text [%], quantity, assumption, kind): the
# 95 % interval under the alternative (``interval``), the variance share it carries
# (``share``), or a row of docs/error-model.md's tables (``row``: "| words | lo–hi | share ± e %
# or none | Δelpd ± se |"); see :func:`width_quote_errors`
WIDTH_QUOTES = [
    ("docs/paper.md", "| 5.95–7.46 |", "tis_70deg", "out_of_plane", "interval"),
    ("docs/posterior.md", "it is 5.95–7.46 %", "tis_70deg", "out_of_plane", "interval"),
    ("docs/run.md", "carries 76 % of TIS(70°)'s", "tis_70deg", "out_of_plane", "share"),
    ("docs/run.md", "carries 61 % of π·BRDF0's", "pi_brdf0", "calibration", "share"),
    *[
        ("docs/error-model.md", row, quantity, assumption, "row")
        for quantity, rows in {
            "tis_70deg": {
                "out_of_plane": "| 5.95–7.46 | 76 ± 1 % | +0.0 ± 0.0 |",
                "calibration": "| 5.75–8.44 | 24 ± 5 % | −0.3 ± 0.7 |",
                "sample_effect": "| 5.40–8.38 | 6 ± 6 % | −1.0 ± 1.2 |",
                "angle_errors": "| 5.30–8.65 | none (wider) | −11.5 ± 3.3 |",
            },
            "pi_brdf0": {
                "out_of_plane": "| 3.59–4.57 | 0 ± 0 % | +0.0 ± 0.0 |",
                "calibration": "| 3.90–4.51 | 61 ± 3 % | −0.3 ± 0.7 |",
                "sample_effect": "| 3.58–4.53 | 5 ± 4 % | −1.0 ± 1.2 |",
                "angle_errors": "| 3.36–4.60 | none (wider) | −11.5 ± 3.3 |",
            },
        }.items()
        for assumption, row in rows.items()
    ],
]
ROW = re.compile(
    r"\| (?P<lo95>[\d.]+)–(?P<hi95>[\d.]+) \| (?:(?P<share>\d+) ± \d+ %|none \(wider\)) \| "
    r"(?P<elpd>[+−-][\d.]+) ± (?P<se>[\d.]+) \|"
)


def width_quote_errors(summary: dict, quotes=WIDTH_QUOTES) -> list[str]:
    """What of ``quotes`` (:data:`WIDTH_QUOTES`) disagrees with a run's ``summary``: each
    interval end and variance share within the two runs' Monte Carlo errors (the record's
    own, taken alike for both runs) plus half the last printed unit; a Δelpd, whose Monte Carlo
    error the record does not hold, within half its standard error (what the docs read from it:
    the data's judgement against that se); "none (wider)" where the record has no share. A
    quote of an alternative the run could not compute (a refit left out) is passed over."""
    errors = []
    for path, text, quantity, assumption, kind in quotes:
        if text not in (REPO / path).read_text():
            errors.append(f"{path} no longer quotes {text!r}: update WIDTH_QUOTES")
            continue
        entry = summary["width"][quantity]["without"][assumption]
        if entry["method"] == "unreliable":
            continue
        found = {}
        if kind == "interval":
            found = dict(zip(("lo95", "hi95"), re.findall(r"\d+\.\d+", text), strict=True))
        elif kind == "share":
            found = {"share": re.search(r"(\d+) %", text)[1]}
        else:
            found = {k: v for k, v in ROW.search(text).groupdict().items() if k != "se"}
            if found["share"] is None:
                found.pop("share")
                if entry["variance_share"] is not None:
                    errors.append(f"{path}: {assumption} of {quantity} has a share now")
        for key, number in found.items():
            value = float(number.replace("−", "-"))
            if key == "elpd":
                run, tolerance = entry["delta_elpd"], 0.5 * entry["delta_elpd_se"] + 0.05
            elif key == "share":
                run = 100 * entry["variance_share"]
                mcse = 100 * entry["variance_share_mcse"]
                tolerance = two_runs_tolerance(mcse, mcse, printed_unit(number))
            else:
                run, mcse = 100 * entry[key], 100 * entry[f"mcse_{key}"]
                tolerance = two_runs_tolerance(mcse, mcse, printed_unit(number))
            if abs(value - run) > tolerance:
                errors.append(
                    f"{path}: {quantity} {assumption} {key} {number} against {run:.3f} from a "
                    f"run (tolerance {tolerance:.3f})"
                )
    return errors


# Quotes of where the article's values fall (file, text, quantity): the posterior quantile
# of the reference value, within its Monte Carlo error (as above)
REFERENCE_QUOTES = [
    ("docs/posterior.md", "(posterior quantile 0.10)", "tis_70deg"),
    ("docs/posterior.md", "(0.028 ± 0.003)", "pi_brdf0"),
    ("docs/run.md", "π·BRDF0 3.6 % (posterior quantile 0.028 ± 0.003)", "pi_brdf0"),
    ("docs/run.md", "BRDF0 0.0114 sr⁻¹\n(posterior quantile 0.023 ± 0.003)", "brdf0"),
    ("docs/instruments.md", "| 0.10 (inside) |", "tis_70deg"),
    ("docs/instruments.md", "| 0.028 ± 0.003 (at the edge) |", "pi_brdf0"),
    ("docs/instruments.md", "| 0.023 ± 0.003 (at the edge) |", "brdf0"),
]
# The docs' quotes of the speed report: (file, pattern with the groups cold and warm [s]),
# the report's row (command), one quote per line of the table
COLD, WARM = r"(?P<cold>\d+) s", r"(?P<warm>\d+) s"
MAIN_JOB = rf"{COLD} on a 2-core machine the first\s+time and {WARM}"
TIME_QUOTES = [
    ("README.md", MAIN_JOB, "run"),
    ("docs/install.md", MAIN_JOB, "run"),
    ("docs/run.md", rf"{COLD} the first time after a change and {WARM} warm", "run"),
    ("docs/benchmarks.md", rf"`run lya` {COLD} cold, {WARM} warm", "run"),
    ("docs/benchmarks.md", rf"`posterior lya` {COLD} cold and {WARM} warm", "posterior"),
]
SPEED_REPORT = REPO / "reports" / "benchmarks-speed.md"


def monte_carlo_tolerance(q: float, sd: float, ess: float) -> float:
    """How far two runs' estimates of the ``q`` quantile may lie apart: 4 standard errors of
    their difference, each run's error that of a normal posterior's quantile from ``ess``
    independent draws, sqrt(q (1 − q) / ess) / φ(z_q) × sd (1.25 sd/√ess for the median,
    2.7 sd/√ess for a 95 % bound), the two runs counted alike (× √2); plus half a unit of the
    docs' last printed digit (0.005 percentage points)."""
    density = stats.norm.pdf(stats.norm.ppf(q))
    error = math.sqrt(q * (1 - q) / ess) / density * sd
    return 4 * math.sqrt(2) * error + 0.5e-4


def quoted_numbers(path: str, text: str) -> list[float]:
    """The numbers of ``text`` [%], which ``path`` must hold, as fractions."""
    content = (REPO / path).read_text()
    assert text in content, f"{path} no longer quotes {text!r}: update BUNDLED_RUN_QUOTES"
    return [float(n) / 100 for n in re.findall(r"\d+\.\d+", text)]


@pytest.fixture(scope="module")
def bundled_quantities(nuts_run):
    """Quantity → {"median", "lo95", "hi95"} of the suite's run, as fractions."""
    summary = nuts_run.summary
    bands = json.loads((nuts_run.out / "bands.json").read_text())
    at = bands["tis"]["theta_i_deg"].index(85.0)
    quantities = {
        "tis_70deg": summary["tis_70deg"],
        "pi_brdf0": summary["pi_brdf0"],
        "tis_85deg": {key: bands["tis"][key][at] for key in ("median", "lo95", "hi95")},
        "new_part_tis_70deg": summary["targets"]["new_part"]["tis_70deg"],
        "measured_tis_70deg": summary["targets"]["measured"]["tis_70deg"],
        "sample_sd": summary["noise"]["sample_sd"],
        "brdf0": dict(
            zip(
                ("median", "lo95", "hi95"),
                np.quantile(np.asarray(nuts_run.idata.posterior["brdf0"]), [0.5, 0.025, 0.975]),
                strict=True,
            )
        ),
    }
    return quantities


@pytest.fixture(scope="module")
def folded(nuts_run):
    """``brdf-infer tis --run DIR --fold --theta-i 70 85`` of the suite's run."""
    import contextlib
    import io

    from brdf_infer.cli import main

    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        code = main(
            ["tis", "--run", str(nuts_run.out), "--fold", "--theta-i", "70", "85", "--json"]
        )
    assert code == 0
    band = json.loads(stdout.getvalue())
    assert band["fold"] is True
    return {
        f"tis_{angle:g}deg_fold": {key: band[key][i] for key in ("median", "lo95", "hi95")}
        for i, angle in enumerate(band["theta_i_deg"])
    }


@pytest.mark.parametrize(
    ("path", "text", "quantity", "keys"),
    BUNDLED_RUN_QUOTES,
    ids=[f"{p}:{q}:{t.strip('| *')}" for p, t, q, _ in BUNDLED_RUN_QUOTES],
)
def test_the_docs_quote_of_the_bundled_run_agrees_with_a_run(
    nuts_run, bundled_quantities, folded, path, text, quantity, keys
):
    run = {**bundled_quantities, **folded}[quantity]
    diagnostics = nuts_run.summary["diagnostics"]
    # the posterior sd from the run's 95 % interval; the smallest ESS over the parameters
    # (bulk for the median, tail for the bounds): the derived quantities' own are not stored
    sd = (run["hi95"] - run["lo95"]) / (2 * stats.norm.ppf(0.975))
    quoted = quoted_numbers(path, text)
    for key, value in zip(keys.split(), quoted, strict=True):
        q = {"median": 0.5, "lo95": 0.025, "hi95": 0.975}[key]
        ess = diagnostics["ess_bulk_min" if key == "median" else "ess_tail_min"]
        tolerance = monte_carlo_tolerance(q, sd, ess)
        assert abs(value - run[key]) <= tolerance, (
            f"{path}: {key} {100 * value:.2f} % against {100 * run[key]:.3f} % from a run "
            f"(tolerance {100 * tolerance:.3f} percentage points)"
        )


def speed_report_times() -> dict[str, dict[str, float]]:
    """Command ("run", "posterior") → cache ("cold", "warm") → wall time end to end [s], from
    the main job's table of the speed report."""
    times: dict[str, dict[str, float]] = {}
    for command, cache, seconds in re.findall(
        r"^\| `brdf-infer (\w+) lya` \| (cold|warm) \| ([\d.]+) \|", SPEED_REPORT.read_text(), re.M
    ):
        times.setdefault(command, {})[cache] = float(seconds)
    assert set(times) == {"run", "posterior"}, times
    return times


@pytest.mark.parametrize(
    ("path", "pattern", "command"), TIME_QUOTES, ids=[q[0] for q in TIME_QUOTES]
)
def test_the_docs_quote_the_speed_report_times(path, pattern, command):
    """A quoted time is the report's, rounded to the second; the file also names the report."""
    content = (REPO / path).read_text()
    found = re.search(pattern, content)
    assert found, f"{path} no longer quotes the main job's time as {pattern!r}"
    report = speed_report_times()[command]
    for cache in ("cold", "warm"):
        assert int(found[cache]) == round(report[cache]), (
            f"{path} says {command} {cache} {found[cache]} s, reports/benchmarks-speed.md "
            f"{report[cache]} s"
        )
    assert "benchmarks-speed.md" in content, f"{path} does not say where its times come from"


def test_every_option_the_docs_give_a_command_is_one_it_takes():
    """A command quoted in the docs (`brdf-infer COMMAND ... --option`) is given only options
    that command accepts (docs/scenes.md once advised `run --target-accept`, a posterior's)."""
    from brdf_infer.cli import build_parser

    commands = next(
        action.choices
        for action in build_parser()._actions
        if isinstance(getattr(action, "choices", None), dict)
    )
    files = [REPO / "README.md", REPO / "notebooks" / "README.md", *(REPO / "docs").glob("*.md")]
    wrong = []
    for path in files:
        for command, rest in re.findall(r"`brdf-infer ([a-z]+)([^`]*)`", path.read_text()):
            assert command in commands, f"{path.name}: no command {command!r}"
            known = {o for action in commands[command]._actions for o in action.option_strings}
            for option in re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", rest):
                if option not in known:
                    wrong.append(f"{path.name}: brdf-infer {command} {option}")
    assert not wrong, wrong


# The docs' quotes of the benchmark's cost curve (reports/benchmarks.md): (file, rows, posterior
# wall [s] as the docs print them); each must be that row's "posterior wall [s]" cell
COST_QUOTES = [
    ("docs/scenes.md", "1986", "30.5"),
    ("docs/scenes.md", "19637", "243.7"),
    ("docs/scenes.md", "59585", "474.9"),
]


@pytest.mark.parametrize(("path", "rows", "seconds"), COST_QUOTES)
def test_the_docs_quote_the_cost_curve_as_the_benchmark_measured_it(path, rows, seconds):
    report = (REPO / "reports" / "benchmarks.md").read_text()
    section = report[report.index("## Cost against the number of rows") :]
    header = next(line for line in section.splitlines() if line.startswith("| table |"))
    column = [cell.strip() for cell in header.strip("|").split("|")].index("posterior wall [s]")
    row = next(
        line for line in section.splitlines() if line.startswith("|") and f"| {rows} |" in line
    )
    assert [cell.strip() for cell in row.strip("|").split("|")][column] == seconds
    quoted = re.sub(r"\s+", " ", (REPO / path).read_text())
    assert (
        f"{seconds} s for {rows} rows" in quoted
        or f"{seconds} s for the full grid of {rows} rows" in quoted
    )


def two_runs_tolerance(mcse_a: float, mcse_b: float, digit: float) -> float:
    """How far two runs' Monte Carlo estimates may lie apart: 4 standard errors of their
    difference (each run's own), plus half the docs' last printed unit ``digit``."""
    return 4 * math.hypot(mcse_a, mcse_b) + 0.5 * digit


def printed_unit(number: str) -> float:
    """The unit of the last printed digit of ``number`` ("0.028" → 0.001, "76" → 1)."""
    return 10.0 ** -len(number.split(".")[1]) if "." in number else 1.0


def test_the_docs_quote_of_what_carries_the_width_agrees_with_a_run(nuts_run):
    """Every quote of the width record against the suite's run (its refits left out: the
    angle errors' rows are checked against the main job's run, tests/test_cli.py)."""
    assert not width_quote_errors(nuts_run.summary)


@pytest.mark.parametrize(
    ("path", "text", "quantity"), REFERENCE_QUOTES, ids=[f"{p}:{q}" for p, _, q in REFERENCE_QUOTES]
)
def test_the_docs_quote_of_where_the_article_lies_agrees_with_a_run(nuts_run, path, text, quantity):
    content = (REPO / path).read_text()
    assert text in content, f"{path} no longer quotes {text!r}: update REFERENCE_QUOTES"
    entry = next(r for r in nuts_run.summary["reference"] if r["quantity"] == quantity)
    quoted = re.search(r"(?:quantile |\(|\| )(0\.\d+)", text)[1]
    tolerance = two_runs_tolerance(
        entry["quantile_mcse"], entry["quantile_mcse"], printed_unit(quoted)
    )
    assert abs(float(quoted) - entry["posterior_quantile"]) <= tolerance, (
        path,
        quoted,
        entry["posterior_quantile"],
        tolerance,
    )


def test_the_docs_quote_of_the_prior_predictive_interval_agrees_with_a_run(nuts_run):
    """docs/error-model.md's TIS(70°) prior predictive interval (4000 draws of the physical
    prior): each end within 4 Monte Carlo standard errors of two runs' difference, on ln TIS,
    where a normal quantile's error is √(q(1 − q)/n)/φ(z_q) × sd: the sd of ln TIS from the
    interval itself (sd ≈ 1.7, so the ends may differ by about ×1.5)."""
    quote = "is 0.071–60 % for\nTIS(70°)"
    assert quote in (REPO / "docs" / "error-model.md").read_text()
    prior = nuts_run.summary["width"]["tis_70deg"]["prior"]
    low, high = (float(n) / 100 for n in re.findall(r"\d+(?:\.\d+)?", quote)[:2])
    sd = math.log(high / low) / (2 * stats.norm.ppf(0.975))
    error = math.sqrt(0.025 * 0.975 / 4000) / stats.norm.pdf(stats.norm.ppf(0.975)) * sd
    for quoted, run in ((low, prior["lo95"]), (high, prior["hi95"])):
        assert abs(math.log(quoted / run)) <= 4 * math.sqrt(2) * error, (quoted, run)


def _table_rows(text: str, heading: str) -> list[list[str]]:
    """The cells of every row of the first table after ``heading`` in ``text``."""
    section = text[text.index(heading) :]
    lines = section.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("|"))
    rows = []
    for line in lines[start + 2 :]:
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in line.strip("|").split("|")])
    return rows


def test_the_docs_quote_the_model_check_power_as_the_benchmark_measured_it():
    """docs/benchmarks.md's table of the model check's power is the report's "any check"
    column, row by row (the fault "none" quoted as "none (false alarms)")."""
    heading = "## Model check: power"
    report = (REPO / "reports" / "benchmarks.md").read_text()
    header = next(
        line for line in report[report.index(heading) :].splitlines() if line.startswith("| fault")
    )
    column = [cell.strip() for cell in header.strip("|").split("|")].index("any check")
    measured = {(row[0], row[1]): row[column] for row in _table_rows(report, heading)}
    quoted = _table_rows((REPO / "docs" / "benchmarks.md").read_text(), heading)
    assert len(quoted) == len(measured)
    for fault, size, share in quoted:
        assert measured[(fault.removesuffix(" (false alarms)"), size)] == share, (fault, size)


# docs/posterior.md's table of series II alone (row label → where summary.json holds it)
SERIES_II_TABLE = "| series II alone, TIS(70°), 95 %"
SERIES_II_ROWS = {
    "the sample measured": ("targets", "measured"),
    "the coating": ("targets", "coating"),
    "a new part": ("targets", "new_part"),
    "without the sample effect": ("width", "sample_effect"),
}


@pytest.mark.slow
def test_the_docs_table_of_series_ii_alone_agrees_with_its_runs(nuts_run, tmp_path):
    """Each interval of the table (τ's default prior; τ from a run of the bundled scene, here
    the suite's) against a run of the same scene: the one-sample answer for the sample
    measured, the coating, a new part, without the sample effect, and τ, each end within
    :func:`two_runs_tolerance` of its Monte Carlo error (from the run's own draws: the
    one-sample posterior's upper tail is long, which an error from the interval's width as a
    normal's understates)."""
    import numpy as np

    from brdf_infer.posterior import load_run_target, run_posterior
    from brdf_infer.scene import load_scene
    from tests.helpers import mcmc_quantile_se, series_ii_scene_file

    text = (REPO / "docs" / "posterior.md").read_text()
    rows = {row[0]: row[1:] for row in _table_rows(text, SERIES_II_TABLE)}
    errors = ("", f'sample_sd_from = "{nuts_run.out}"')
    levels = {"median": 0.5, "lo95": 0.025, "hi95": 0.975}
    for column, lines in enumerate(errors):
        folder = tmp_path / f"column{column}"
        folder.mkdir()
        scene = load_scene(series_ii_scene_file(folder, lines))
        run = run_posterior(  # the docs' settings: `posterior --draws 4000`
            scene, scene.load_measurements(), out=folder / "run", progress=False, draws=4000
        )
        chains = run.summary["settings"]["chains"]
        found, draws = {}, {}
        for label, (record, key) in SERIES_II_ROWS.items():
            if record == "targets":
                found[label] = run.summary["targets"][key]["tis_70deg"]
                member, physical, _ = load_run_target(folder / "run", key)
                values = np.exp(np.asarray(member.log_tis_draws(np.array([70.0]), physical)))
                draws[label] = values.reshape(chains, -1)
            else:
                found[label] = run.summary["width"]["tis_70deg"]["without"][key]
        found["τ (median and 95 %)"] = run.summary["noise"]["sample_sd"]
        draws["τ (median and 95 %)"] = np.asarray(run.idata.posterior["sample_sd"])
        for label, entry in found.items():
            numbers = re.findall(r"\d+\.\d+", rows[label][column])
            keys = ("median", "lo95", "hi95") if len(numbers) == 3 else ("lo95", "hi95")
            for key, number in zip(keys, numbers, strict=True):
                if label in draws:
                    error = 100 * mcmc_quantile_se(draws[label], levels[key])
                else:
                    error = 100 * entry[f"mcse_{key}"]
                tolerance = two_runs_tolerance(error, error, printed_unit(number))
                run_value = 100 * entry[key]
                assert abs(float(number) - run_value) <= tolerance, (
                    f"series II column {column}, {label} {key}: {number} % against "
                    f"{run_value:.3f} % (tolerance {tolerance:.3f})"
                )
