"""Every malformed input is one clear line on stderr naming file/row/field, exit code 2."""

import json
from pathlib import Path

import pytest

from brdf_infer.errors import BadInputError
from brdf_infer.tables.measurements import load_measurements
from tests.helpers import run_cli, run_cli_process

HEADER = "series,sample,theta_i_deg,theta_s_deg,reflectance,reflectance_err"
GOOD_ROWS = [
    "I,1,18,18,5.79e-05,3.3e-06",
    "I,1,45,45,8.46e-05,5.7e-06",
    "I,1,75,75,8.37e-04,4.9e-05",
    "I,1,80,80,1.22e-03,1.0e-04",
    "I,2,80,80,1.15e-03,9.0e-05",
]
SCENE = """name = "tiny"
measurements = "m.csv"
[series.I]
aperture_diameter_mm = 7.2
aperture_distance_mm = 103.8
[errors]
reflectance_rel = 0.065
"""


def write_scene(directory: Path, csv_text: str | None, scene_text: str = SCENE) -> Path:
    if csv_text is not None:
        (directory / "m.csv").write_text(csv_text)
    scene = directory / "scene.toml"
    scene.write_text(scene_text)
    return scene


def expect_bad_input(capsys, *argv, match: str) -> str:
    code, out, err = run_cli(*argv, capsys=capsys)
    assert code == 2, (code, out, err)
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    assert match in lines[0], lines[0]
    return lines[0]


def with_row(row: str, position: int = 2) -> str:
    rows = list(GOOD_ROWS)
    rows.insert(position, row)
    return "\n".join([HEADER, *rows]) + "\n"


CSV_CASES = {
    "missing column": (
        HEADER.replace(",reflectance,", ",") + "\nI,1,18,18,3e-6\n",
        "field 'reflectance'",
    ),
    "semicolons": (
        HEADER.replace(",", ";") + "\nI;1;18;18;5e-5;3e-6\n",
        "separate the columns with commas",
    ),
    "duplicated column": (
        HEADER + ",sample\n" + GOOD_ROWS[0] + ",x\n",
        "field 'sample': column appears twice",
    ),
    "more cells than header": (with_row("I,1,30,30,1e-4,1e-5,7"), "row 3 (line 4): 7 cells"),
    "non-numeric cell": (
        with_row("I,1,30,30,abc,1e-5"),
        "row 3 (line 4), field 'reflectance': not a number",
    ),
    "nan": (with_row("I,1,30,nan,1e-4,1e-5"), "field 'theta_s_deg': not a finite number"),
    "inf": (with_row("I,1,30,30,1e-4,inf"), "field 'reflectance_err': not a finite number"),
    "reflectance zero": (
        with_row("I,1,30,30,0,1e-5"),
        "field 'reflectance': raw reflectance must lie in (0, 1)",
    ),
    "reflectance negative": (with_row("I,1,30,30,-1e-4,1e-5"), "field 'reflectance'"),
    "reflectance one": (with_row("I,1,30,30,1,1e-5"), "field 'reflectance'"),
    "negative sigma": (
        with_row("I,1,30,30,1e-4,-1e-5"),
        "field 'reflectance_err': uncertainty must be >= 0",
    ),
    "theta_i 90": (
        with_row("I,1,90,30,1e-4,1e-5"),
        "field 'theta_i_deg': incidence angle must lie in [0, 90)",
    ),
    "theta_i negative": (with_row("I,1,-1,30,1e-4,1e-5"), "field 'theta_i_deg'"),
    "theta_s above 90": (
        with_row("I,1,30,90.5,1e-4,1e-5"),
        "field 'theta_s_deg': scattering angle must lie in [-90, 90]",
    ),
    "theta_s below -90": (with_row("I,1,30,-91,1e-4,1e-5"), "field 'theta_s_deg'"),
    "unknown series": (
        with_row("III,1,30,30,1e-4,1e-5"),
        "field 'series': series 'III' is not defined",
    ),
    "duplicate row": (with_row(GOOD_ROWS[0], 5), "row 6 (line 7): duplicate of row 1"),
    "empty cell": (with_row("I,,30,30,1e-4,1e-5"), "field 'sample': empty cell"),
    "empty file": ("", "empty file"),
    "header only": (HEADER + "\n", "no measurement rows"),
}


@pytest.mark.parametrize("case", CSV_CASES)
def test_malformed_measurement_csv(tmp_path, capsys, case):
    text, match = CSV_CASES[case]
    scene = write_scene(tmp_path, text)
    line = expect_bad_input(capsys, "fit", str(scene), match=match)
    assert "m.csv" in line


def test_a_nul_character_is_refused_with_its_line(tmp_path):
    """Found by the generated inputs: a NUL after a name ('1\\x00') was dropped by NumPy, so
    two different rows became duplicates in the loaded table."""
    path = tmp_path / "m.csv"
    path.write_bytes(with_row('II,"1"\x00,30,30,1e-4,1e-5').encode())
    with pytest.raises(BadInputError, match=r"m.csv, line 4: contains a NUL character"):
        load_measurements(path)


def test_missing_and_unreadable_measurement_paths(tmp_path, capsys):
    scene = write_scene(tmp_path, None)
    message = expect_bad_input(capsys, "fit", str(scene), match="no such file: ")
    assert str((tmp_path / "m.csv").resolve()) in message and "scene 'tiny'" in message
    (tmp_path / "m.csv").mkdir()
    expect_bad_input(capsys, "fit", str(scene), match="is not a file")


def test_extra_named_columns_are_ignored(tmp_path, capsys):
    text = "\n".join([HEADER + ",note", *(row + ",ok" for row in GOOD_ROWS)]) + "\n"
    code, out, err = run_cli(
        "fit", str(write_scene(tmp_path, text)), "--selection", "samples", "--json", capsys=capsys
    )
    assert code == 0, err
    assert json.loads(out)["n_points"] == 5


def test_loader_error_carries_file_row_and_field(tmp_path):
    path = tmp_path / "m.csv"
    path.write_text(with_row("I,1,30,30,2,1e-5"))
    with pytest.raises(BadInputError) as info:
        load_measurements(path)
    assert (info.value.row, info.value.line, info.value.field) == (3, 4, "reflectance")


SCENE_CASES = {
    "unknown top-level key": ("colour = 'black'\n" + SCENE, "field 'colour': unknown key"),
    "unknown nested key": (
        SCENE.replace("[errors]", "[errors]\nreflectance_abs = 1"),
        "field 'errors.reflectance_abs'",
    ),
    "wrong type": (
        SCENE.replace("= 7.2", '= "7.2"'),
        "field 'series.I.aperture_diameter_mm': expected a number",
    ),
    "non-positive aperture": (SCENE.replace("= 7.2", "= 0"), "must be > 0"),
    "missing measurements": (
        SCENE.replace('measurements = "m.csv"\n', ""),
        "field 'measurements': missing",
    ),
    "no series": (SCENE.split("[series.I]")[0], "field 'series'"),
    "toml syntax": (SCENE + "[errors\n", "invalid TOML"),
    "unknown error model": (
        SCENE.replace("[errors]", '[errors]\nmodel = "gaussian"'),
        "field 'errors.model': expected one of generative, spread",
    ),
    "the replaced kind of the relative error": (
        SCENE.replace("[errors]", '[errors]\nreflectance_rel_kind = "calibration"'),
        "field 'errors.reflectance_rel_kind': replaced by errors.calibration",
    ),
    "unknown calibration": (
        SCENE.replace("[errors]", '[errors]\ncalibration = "shared"'),
        "field 'errors.calibration': expected one of per_series, per_sample, none",
    ),
    "negative calibration size": (
        SCENE.replace("[errors]", "[errors]\ncalibration_rel = -0.1"),
        "field 'errors.calibration_rel': must be >= 0",
    ),
    "unknown rotation coupling": (
        SCENE.replace("[errors]", '[errors]\nrotation_coupling = "camera_moves"'),
        "field 'errors.rotation_coupling': expected one of camera_follows, camera_fixed",
    ),
    "images per row not a positive integer": (
        SCENE.replace("[errors]", "[errors]\nimages_per_row = 0"),
        "field 'errors.images_per_row': expected a positive integer",
    ),
    "images per row of a series not a positive integer": (
        SCENE.replace("[errors]", "[errors]\nimages_per_row = { I = 2.5 }"),
        "field 'errors.images_per_row.I': expected a positive integer",
    ),
    "images per row of an unknown series": (
        SCENE.replace("[errors]", "[errors]\nimages_per_row = { I = 12, III = 3 }"),
        "field 'errors.images_per_row.III': no series 'III' in the scene",
    ),
    "negative repeatability": (
        SCENE.replace("[errors]", "[errors]\nrepeatability = -0.1"),
        "field 'errors.repeatability': must be >= 0",
    ),
    "repeatability neither learned nor a number": (
        SCENE.replace("[errors]", '[errors]\nrepeatability = "auto"'),
        "field 'errors.repeatability'",
    ),
    "unknown angle method": (
        SCENE.replace("[errors]", '[errors]\nangle_method = "exact"'),
        "field 'errors.angle_method'",
    ),
    # found by the generated inputs (tests/test_loader_inputs.py): each was a traceback, a
    # message of two lines, or a scene that loaded and failed later
    "a key with a line break": (
        SCENE.replace("[errors]", '[errors]\n"a\\nb" = 1'),
        "field 'errors.a\\nb': unknown key",
    ),
    "instrument nodes a list": (SCENE + "[instrument]\nnodes = [3]\n", "'instrument.nodes'"),
    "reference parameters a list": (
        SCENE + "[outputs]\nreference_params = ['uv-paper']\n",
        "field 'outputs.reference_params'",
    ),
    "a measurements name too long": (
        SCENE.replace('"m.csv"', '"' + "m" * 300 + '.csv"'),
        "field 'measurements': cannot read (File name too long)",
    ),
    "a NUL in the measurements name": (
        SCENE.replace('"m.csv"', '"m\\u0000.csv"'),
        "field 'measurements': cannot read (embedded null byte)",
    ),
    "a name that climbs out of the results folder": (
        SCENE.replace('name = "tiny"', 'name = "../up"'),
        "field 'name': expected a non-empty name without '/'",
    ),
    "an empty name": (SCENE.replace('name = "tiny"', 'name = " "'), "field 'name'"),
    "an unknown selection": (
        SCENE + "[paper_fit]\nselection = 'all'\n",
        "field 'paper_fit.selection': unknown selection 'all'",
    ),
}


@pytest.mark.parametrize("case", SCENE_CASES)
def test_malformed_scene(tmp_path, capsys, case):
    text, match = SCENE_CASES[case]
    scene = write_scene(tmp_path, "\n".join([HEADER, *GOOD_ROWS]) + "\n", text)
    assert "scene.toml" in expect_bad_input(capsys, "fit", str(scene), match=match)


def test_unknown_scene_name(capsys):
    expect_bad_input(capsys, "fit", "no-such-scene", match="neither a built-in scene")


PARAM_CASES = {
    "missing field": (
        {"brdf0": 0.01, "a1": 1e-4, "a2": 0, "a3": 0, "alpha": 4.5},
        "field 'theta_s0': missing",
    ),
    "non-numeric": (
        {"brdf0": "x", "a1": 1e-4, "a2": 0, "a3": 0, "alpha": 4.5, "theta_s0": -12},
        "field 'brdf0': not a number",
    ),
    "negative brdf0": (
        {"brdf0": -1, "a1": 1e-4, "a2": 0, "a3": 0, "alpha": 4.5, "theta_s0": -12},
        "field 'brdf0': must be > 0",
    ),
    "an integer too large for a float (was a traceback)": (
        {"brdf0": 0.01, "a1": 10**400, "a2": 0, "a3": 0, "alpha": 4.5, "theta_s0": -12},
        "field 'a1': not finite: 1000",
    ),
}


@pytest.mark.parametrize("case", PARAM_CASES)
def test_malformed_parameter_file(tmp_path, capsys, case):
    content, match = PARAM_CASES[case]
    path = tmp_path / "p.json"
    path.write_text(json.dumps(content))
    expect_bad_input(capsys, "tis", "--params", str(path), match=match)


def test_parameter_file_not_json(tmp_path, capsys):
    path = tmp_path / "p.json"
    path.write_text("{brdf0: 1")
    expect_bad_input(capsys, "tis", "--params", str(path), match="not valid JSON")
    path.write_text("[" * 100_000 + "]" * 100_000)  # deeper than the parser's stack
    expect_bad_input(capsys, "tis", "--params", str(path), match="nested too deeply")
    deep = '{"a": ' + "[" * 100_000 + "]" * 100_000 + "}"
    expect_bad_input(capsys, "tis", "--params", deep, match="field '--params': not valid JSON")


def test_bad_options_are_one_line_usage_errors(capsys):
    expect_bad_input(capsys, "tis", "--theta-i", "95", match="outside [0, 90)")
    expect_bad_input(capsys, "tis", "--theta-i", "abc", match="invalid float value")
    expect_bad_input(
        capsys, "brdf", "--theta-i", "10", "20", "--theta-s", "1", "2", "3", match="equal lengths"
    )
    expect_bad_input(capsys, "fit", "--method", "magic", match="invalid choice")


@pytest.mark.full
def test_real_process_prints_no_traceback(tmp_path):
    scene = write_scene(tmp_path, with_row("I,1,30,30,abc,1e-5"))
    result = run_cli_process("fit", str(scene))
    assert result.returncode == 2
    assert result.stdout == ""
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr
    assert "field 'reflectance'" in result.stderr
