"""The run folder's one owner (brdf_infer.runs.folder): its writers and typed readers round
trip, a missing or corrupt record is one clear error naming the file, an old folder without
a study's file reads as None, and no module outside it parses a run folder's JSON itself."""

import ast
import json
from pathlib import Path

import pytest

from brdf_infer.errors import BadInputError
from brdf_infer.runs import folder as run_folder
from brdf_infer.runs.folder import (
    BANDS_FILE,
    COMPARE_FILE,
    DESIGN_FILE,
    INSTRUMENT_FILE,
    SENSITIVITY_FILE,
    SUMMARY_FILE,
    RunFolder,
    read_json_file,
)

ROOT = Path(__file__).resolve().parent.parent
SUMMARY = {"scene": "lya", "sampler": "nuts", "verdict": {"ok": True, "lines": [], "text": "ok"}}
BANDS = {"fold": False, "brdf_inplane": {"theta_i_deg": [18.0], "median": [[1.0]]}}


def test_the_records_round_trip(tmp_path):
    folder = RunFolder(tmp_path / "run")  # created by the first write
    assert folder.write_summary(SUMMARY) == folder.file(SUMMARY_FILE)
    folder.write_bands(BANDS)
    assert folder.summary() == SUMMARY
    assert folder.bands() == BANDS
    assert RunFolder(str(folder.path)).summary() == SUMMARY  # a str is a path too


def test_the_studies_round_trip(tmp_path):
    folder = RunFolder(tmp_path)
    folder.write_studies(["sensitivity"], ["compare: no families named"])
    assert folder.studies() == {"run": ["sensitivity"], "not_run": ["compare: no families named"]}
    for name, read in [
        (COMPARE_FILE, folder.compare),
        (SENSITIVITY_FILE, folder.sensitivity),
        (DESIGN_FILE, folder.design),
        (INSTRUMENT_FILE, folder.instruments),
    ]:
        folder.write_json(name, {"written": name})
        assert read() == {"written": name}
    traces = [{"series": "II", "params_source": "median"}]
    folder.write_traces(traces)
    assert folder.traces() == traces
    exports = [{"format": "zemax-bsdf", "folder": "x", "files": []}]
    folder.write_exports(exports)
    assert folder.exports() == exports
    folder.write_bytes("figures/a.png", b"png")
    assert (folder.figure_dir / "a.png").read_bytes() == b"png"
    assert folder.variant("spread").path == tmp_path / "variants" / "spread"


def test_an_old_folder_without_a_study_reads_as_none(tmp_path):
    folder = RunFolder(tmp_path)
    folder.write_summary(SUMMARY)
    assert folder.studies() is None
    assert folder.compare() is None
    assert folder.sensitivity() is None
    assert folder.design() is None
    assert folder.instruments() is None
    assert folder.traces() == []
    assert folder.exports() == []
    assert folder.variant("spread").read_json(SUMMARY_FILE, optional=True) is None


def test_a_missing_summary_names_the_folder(tmp_path):
    with pytest.raises(BadInputError, match=r"no summary\.json here") as caught:
        RunFolder(tmp_path).summary()
    assert caught.value.file == str(tmp_path)


@pytest.mark.parametrize(
    ("content", "problem"),
    [('{\n  "scene": ', "not valid JSON"), ("[1, 2]", "not a JSON object")],
)
def test_a_corrupt_summary_names_the_file(tmp_path, content, problem):
    (tmp_path / SUMMARY_FILE).write_text(content)
    with pytest.raises(BadInputError, match=problem) as caught:
        RunFolder(tmp_path).summary()
    assert caught.value.file == str(tmp_path / SUMMARY_FILE)
    assert "\n" not in str(caught.value)


def test_a_corrupt_record_of_exports_reads_as_none_recorded(tmp_path):
    (tmp_path / "exports.json").write_text("{")
    assert RunFolder(tmp_path).exports() == []


def test_corrupt_ray_traces_are_an_error(tmp_path):
    (tmp_path / "raytrace.json").write_text(json.dumps({"other": []}))
    with pytest.raises(BadInputError, match="no 'traces'"):
        RunFolder(tmp_path).traces()


def test_read_json_file_names_the_line(tmp_path):
    path = tmp_path / "params.json"
    path.write_text('{\n  "brdf0": 1,\n  oops\n}')
    with pytest.raises(BadInputError, match="not valid JSON") as caught:
        read_json_file(path)
    assert caught.value.line == 3
    with pytest.raises(BadInputError, match="no such file"):
        read_json_file(tmp_path / "absent.json")


def test_a_failed_write_leaves_the_record(tmp_path):
    folder = RunFolder(tmp_path)
    folder.write_bands(BANDS)
    with pytest.raises(TypeError):
        folder.write_bands({"fold": object()})  # not JSON: nothing published
    assert folder.bands() == BANDS
    assert sorted(p.name for p in tmp_path.iterdir()) == [BANDS_FILE]


def _json_reads(tree: ast.AST) -> list[int]:
    """Lines of ``json.loads(<...>.read_text(...))`` and ``json.load(...)`` calls."""
    found = []
    for node in ast.walk(tree):
        if not (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and isinstance(node.func.value, ast.Name)
            and node.func.value.id == "json"
        ):
            continue
        if node.func.attr == "load":
            found.append(node.lineno)
        elif node.func.attr == "loads" and node.args:
            argument = node.args[0]
            if (
                isinstance(argument, ast.Call)
                and isinstance(argument.func, ast.Attribute)
                and argument.func.attr in ("read_text", "read_bytes", "read")
            ):
                found.append(node.lineno)
    return found


def test_no_module_but_run_folder_parses_a_json_file():
    owner = Path(run_folder.__file__).resolve()
    found = []
    for path in sorted((ROOT / "brdf_infer").rglob("*.py")):
        if path.resolve() == owner:
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        found += [f"{path.relative_to(ROOT)}:{line}" for line in _json_reads(tree)]
    assert not found, "JSON files read outside brdf_infer.runs.folder:\n" + "\n".join(found)


def test_the_check_finds_a_planted_read():
    planted = ast.parse(
        "import json\ndef f(p):\n    return json.loads((p / 'summary.json').read_text())\n"
    )
    assert _json_reads(planted) == [3]
    assert _json_reads(ast.parse("import json\nwith open(p) as s:\n    json.load(s)\n")) == [3]
