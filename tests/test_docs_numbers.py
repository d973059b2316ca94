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

import pytest
from scipy import stats

from tests.helpers import REPO

# Quotes of the bundled run: (file, the text as the docs print it [%], quantity, the numbers it
# holds). Quantities: a key of summary.json ("tis_70deg", "pi_brdf0"), "tis_85deg" (bands.json)
# or "tis_70deg_fold" / "tis_85deg_fold" (`brdf-infer tis --run DIR --fold`).
BUNDLED_RUN_QUOTES = [
    ("docs/paper.md", "| 6.65 (95 %: 5.95–7.42) |", "tis_70deg", "median lo95 hi95"),
    ("docs/paper.md", "| 8.83 (7.79–10.02) |", "tis_85deg", "median lo95 hi95"),
    ("docs/paper.md", "| 6.55 (5.86–7.31) |", "tis_70deg_fold", "median lo95 hi95"),
    ("docs/paper.md", "| 8.45 (7.48–9.58) |", "tis_85deg_fold", "median lo95 hi95"),
    ("docs/posterior.md", "TIS(70°) =\n6.65 % (95 %: 5.95–7.42 %", "tis_70deg", "median lo95 hi95"),
    ("docs/posterior.md", "π·BRDF0 = 4.05 % (3.61–4.56 %)", "pi_brdf0", "median lo95 hi95"),
    ("docs/instruments.md", "| 6.65 % (5.95–7.42 %) |", "tis_70deg", "median lo95 hi95"),
    ("docs/instruments.md", "| 4.05 % (3.61–4.56 %) |", "pi_brdf0", "median lo95 hi95"),
    ("docs/instruments.md", "TIS(70°) 6.65 % (5.95–7.42 %)", "tis_70deg", "median lo95 hi95"),
    ("docs/error-model.md", "| `lya`, TIS(70°) | 5.95–7.42 % |", "tis_70deg", "lo95 hi95"),
    ("docs/error-model.md", "| `lya`, π·BRDF0 | 3.61–4.56 % |", "pi_brdf0", "lo95 hi95"),
    # the sensitivity study's baseline (`brdf-infer sensitivity lya`) is the same posterior
    ("docs/error-model.md", "| **6.62 (5.95–7.43)** |", "tis_70deg", "median lo95 hi95"),
    ("docs/error-model.md", "| **4.04 (3.59–4.55)** |", "pi_brdf0", "median lo95 hi95"),
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
