"""The settings records own their defaults and checks: the command line takes its defaults
from them, a notebook gets the same results as the command line, and a record refuses a bad
field by its own name (the command line names the flag)."""

import dataclasses
import inspect
import json
import re
from pathlib import Path

import pytest

from brdf_infer.cli import build_parser
from brdf_infer.errors import BadInputError
from brdf_infer.posterior import run_posterior
from brdf_infer.scene.settings import (
    EMCEE_BURN_IN,
    BatchSettings,
    CompareSettings,
    DesignOptions,
    PosteriorSettings,
    RunSettings,
    SbcSettings,
    SensitivitySettings,
)
from brdf_infer.workflow import lsq_summary
from tests.helpers import SUITE_WARMUP, run_cli

# each record and a command line that takes its defaults (required arguments given)
RECORDS = [
    (RunSettings, ["run"]),
    (PosteriorSettings, ["posterior"]),
    (BatchSettings, ["batch", "lya"]),
    (CompareSettings, ["compare"]),
    (SensitivitySettings, ["sensitivity"]),
    (SbcSettings, ["sbc"]),
    (DesignOptions, ["design", "run-folder"]),
]


def options_of(argv: list[str]) -> dict:
    return vars(build_parser().parse_args(argv))


@pytest.mark.parametrize(("record", "argv"), RECORDS, ids=[r.__name__ for r, _ in RECORDS])
def test_every_cli_default_is_its_settings_records(record, argv):
    options = options_of(argv)
    compared = []
    for field in dataclasses.fields(record):
        if record is DesignOptions and field.name == "budget":
            continue  # design's budget: the scene's [design] budget, whose default is this
        if field.name in options:
            assert options[field.name] == field.default, (argv[0], field.name)
            compared.append(field.name)
        elif field.name == "refit":
            assert options["no_refit"] is not field.default
            compared.append(field.name)
    assert "seed" in compared and len(compared) >= 3, compared


def test_the_library_functions_default_to_the_records():
    """run_posterior holds no copy of PosteriorSettings' fields (it takes the record, or its
    fields by name); ``fit``'s lsq options are lsq_summary's, whose starts are the main
    job's."""
    keywords = inspect.signature(run_posterior).parameters
    assert not {field.name for field in dataclasses.fields(PosteriorSettings)} & set(keywords)
    assert PosteriorSettings().warmup == 1000 and PosteriorSettings(sampler="emcee").warmup == 4000
    options = options_of(["fit"])
    for name, parameter in inspect.signature(lsq_summary).parameters.items():
        if name in options and parameter.default is not inspect.Parameter.empty:
            assert options[name] == parameter.default, name
    assert options["starts"] == RunSettings().lsq_starts
    assert options_of(["design", "run-folder"])["budget"] is None  # the scene's [design] one


@pytest.mark.parametrize(
    ("make", "field", "message"),
    [
        (lambda: RunSettings(warmup=-1), "warmup", "must be >= 0, got -1"),
        (lambda: RunSettings(lsq_starts=0), "lsq_starts", "must be at least 1, got 0"),
        (lambda: RunSettings(model="phong"), "model", "unknown model family 'phong'"),
        (lambda: PosteriorSettings(sampler="hmc"), "sampler", "unknown sampler 'hmc'"),
        (lambda: PosteriorSettings(steps=0), "steps", "must be at least 1, got 0"),
        (lambda: PosteriorSettings(target_accept=1.0), "target_accept", "must lie in (0, 1)"),
        (lambda: BatchSettings(mode="serial"), "mode", "unknown mode 'serial'"),
        (lambda: CompareSettings(warmup=0), "warmup", "must be at least 1, got 0"),
        (lambda: SensitivitySettings(chains=0), "chains", "must be at least 1, got 0"),
        (lambda: SbcSettings(target_accept=0.0), "target_accept", "must lie in (0, 1)"),
        (lambda: SbcSettings(planted_fault="both"), "planted_fault", "unknown planted fault"),
        (lambda: DesignOptions(draws=1), "draws", "expected 50..100000, got 1"),
    ],
)
def test_a_record_refuses_a_bad_field_by_its_own_name(make, field, message):
    with pytest.raises(BadInputError, match=re.escape(message)) as error:
        make()
    assert error.value.field == field


def test_run_posterior_takes_the_record_or_its_fields_by_name():
    """One settings path: the record, its fields by name in place of the record's, and a
    name the record lacks refused by that name before anything is sampled."""
    from brdf_infer.posterior import posterior_settings

    base = PosteriorSettings(chains=2, seed=4)
    assert posterior_settings(base, {"draws": 30}) == PosteriorSettings(chains=2, seed=4, draws=30)
    assert posterior_settings(None, {"sampler": "emcee"}).warmup == EMCEE_BURN_IN
    # a record's warmup that is its sampler's default follows a new sampler; one set stays
    assert posterior_settings(PosteriorSettings(), {"sampler": "emcee"}).warmup == EMCEE_BURN_IN
    assert posterior_settings(PosteriorSettings(warmup=300), {"sampler": "emcee"}).warmup == 300
    with pytest.raises(BadInputError) as error:
        posterior_settings(None, {"thin": 2})
    assert error.value.field == "thin"
    with pytest.raises(BadInputError) as error:
        run_posterior(None, None, chanis=2)  # refused before the scene is touched
    assert error.value.field == "chanis"


def test_the_command_line_names_the_flag_and_creates_nothing(tmp_path, capsys):
    """SBC's target acceptance went unchecked (200 replicates ran at 0): now refused before
    any work, under the flag's name."""
    out = tmp_path / "sbc"
    code, stdout, err = run_cli(
        "sbc", "--target-accept", "0", "--out", str(out), "--json", capsys=capsys
    )
    assert (code, stdout) == (2, "")
    assert err == "brdf-infer: error: field '--target-accept': must lie in (0, 1), got 0.0\n"
    assert not out.exists()


def test_no_library_error_names_a_command_line_flag():
    package = Path(__file__).resolve().parents[1] / "brdf_infer"
    offenders = [
        f"{path.relative_to(package)}: {line.strip()}"
        for path in package.rglob("*.py")
        if "cli" not in path.relative_to(package).parts
        for line in path.read_text().splitlines()
        if re.search(r"""field=f?["']--""", line)
    ]
    assert offenders == []


def _comparable(payload: dict, out: Path) -> str:
    """``run``'s JSON without wall times, its folder written as OUT."""

    def scrub(value):
        if isinstance(value, dict):
            return {k: "t" if "seconds" in k else scrub(v) for k, v in value.items()}
        if isinstance(value, list):
            return [scrub(v) for v in value]
        return value

    return json.dumps(scrub(payload)).replace(str(out), "OUT")


@pytest.mark.usefixtures("width_refit_off")  # the same path either way; a refit is a sampler
def test_workflow_run_and_the_command_line_give_the_same_result(
    lya, nuts_run, tmp_path, capsys, monkeypatch
):
    """A notebook's ``workflow.run`` and ``brdf-infer run`` with the same settings give the
    same result (with the same defaults, checked above): one chain, the suite's warmup (in
    ``nuts_run``'s group its compiled programs are warm), few draws; the HTML report's
    figures are left out of both (the verdict is the one the run recorded)."""
    from brdf_infer.verdict import Verdict
    from brdf_infer.workflow import run

    def recorded_verdict(out: Path, progress=None) -> tuple[Path, Verdict]:
        summary = json.loads((out / "summary.json").read_text())
        return out / "report.html", Verdict.from_json(summary["verdict"])

    monkeypatch.setattr("brdf_infer.report.write_report", recorded_verdict)
    # 1 × 20 draws: the shapes of test_report's small runs, whose compiled programs are reused
    settings = {"chains": 1, "warmup": SUITE_WARMUP, "draws": 20, "seed": 3}
    library = tmp_path / "library"
    result = run(*lya, library, RunSettings(**settings))
    command = tmp_path / "command"
    argv = [f"--{name}={value}" for name, value in settings.items()]
    code, stdout, err = run_cli("run", "--out", str(command), *argv, "--json", capsys=capsys)
    assert code == 0, err
    assert _comparable(json.loads(stdout), command) == _comparable(result.as_json(), library)
    for name in ("summary.json", "fit_lsq.json", "bands.json"):
        written = [json.loads((out / name).read_text()) for out in (library, command)]
        assert _comparable(written[1], command) == _comparable(written[0], library), name
