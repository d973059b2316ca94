"""The typed records of a posterior run (summary.json, bands.json) hold what runs write."""

import json

import pytest

from brdf_infer.posterior import run_posterior
from brdf_infer.runs.records import Bands, PosteriorSummary
from tests.helpers import record_mismatches


def test_a_nuts_runs_files_are_its_records(nuts_run):
    for name, record in (("summary.json", PosteriorSummary), ("bands.json", Bands)):
        written = json.loads((nuts_run.out / name).read_text())
        assert record_mismatches(written, record) == [], name
    assert record_mismatches(nuts_run.summary, PosteriorSummary) == []


# 18 walkers on lya (2 × its 9 sampled dimensions): the emcee programs (MAP search, potential)
# of test_posterior's emcee18 tests, which compile the data in; in their group, one compile for
# the three
@pytest.mark.full
@pytest.mark.xdist_group("emcee18")
def test_an_emcee_runs_summary_is_its_record(lya, tmp_path):
    run = run_posterior(
        *lya,
        sampler="emcee",
        walkers=18,
        steps=300,
        warmup=100,
        out=tmp_path,
        progress=False,
        seed=1,
    )
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert record_mismatches(summary, PosteriorSummary) == []
    assert "autocorrelation_time_max" in summary["diagnostics"]
    assert record_mismatches(run.bands, Bands) == []


def test_the_record_check_finds_a_missing_a_foreign_and_a_mistyped_key(nuts_run):
    """Planted faults: each must be found."""
    summary = json.loads((nuts_run.out / "summary.json").read_text())
    del summary["predictive"]["elpd_loo"]
    summary["diagnostics"]["undeclared"] = 1
    summary["tis_70deg"]["median"] = "6 %"
    summary["verdict"]["ok"] = 1
    assert sorted(record_mismatches(summary, PosteriorSummary)) == [
        ".diagnostics.undeclared: not declared",
        ".predictive.elpd_loo: missing",
        ".tis_70deg.median: not a number",  # neither a Band nor None
        ".verdict.ok: not bool",
    ]
