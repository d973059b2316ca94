"""Generated inputs for every loader (Hypothesis strategies) and the check each must pass.

Every loader of user files — the measurement CSV (both quantities, ``phi_s_deg``), the scene
TOML (every table and key), a Zemax tabular ``.BSDF`` file and a parameter JSON file or inline
object — must end each input in a result or in one :class:`~brdf_infer.errors.BadInputError`
(one line naming the file or option, exit 2 on the command line): never another exception,
never a file written. A result must hold what the loader promises (finite angles in range,
positive values, no duplicate rows, …).

The strategies start from well-formed files and break them the ways files from other tools
and hands are broken: delimiters, encodings and byte-order marks, line endings, quoting,
huge, tiny and non-finite numbers, duplicated rows and columns, wrong types and unknown keys,
missing and odd paths, header lines out of order, counts that disagree with the data, tabs,
truncation. ``tests/test_loader_inputs.py`` runs them in the suite (a fast profile) and in the
``slow`` set (5,000 inputs per loader); :func:`brdf_infer.bench._robustness.loader_rows`
counts them for the benchmark. Needs Hypothesis (the ``test`` extra).
"""

from __future__ import annotations

import json
import math
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import strategies as st

from brdf_infer.errors import BadInputError
from brdf_infer.measurements import Measurements

# ----------------------------------------------------------------------------- numbers as text

_ODD_NUMBERS = [
    "0", "-0", "1", "-1", "90", "-90", "89.999999", "90.0000001", "180", "360", "-360", "1e-300",
    "5e-324", "1e300", "1e308", "1e999", "-1e999", "nan", "NaN", "inf", "-inf", "Infinity",
    "1_000", "0x10", "1,5", "１２", " 3 ", "", " ", "abc", "1e", ".", "+.5", "٣", "1/2",
]  # fmt: skip


def _number_text(low: float, high: float, odd: bool = True) -> st.SearchStrategy[str]:
    """Text of a number in [low, high], formatted several ways; ``odd``: often anything."""
    inside = st.floats(low, high, allow_nan=False).flatmap(
        lambda v: st.sampled_from([repr(v), f"{v:g}", f"{v:.3e}", f"{v:.17g}", f" {v:.6g} "])
    )
    if not odd:
        return inside
    anywhere = st.floats(allow_nan=True, allow_infinity=True).map(repr)
    return st.one_of(inside, st.sampled_from(_ODD_NUMBERS), anywhere)


# Each input is drawn with a level of damage: 0 a well-formed file (half the inputs), 1 and 2
# some things broken, 3 many. ``_broken(draw, level, one_in)`` decides one thing.
_LEVELS = st.sampled_from([0, 0, 0, 1, 1, 2, 3])


def _broken(draw, level: int, one_in: int) -> bool:
    return level > 0 and draw(st.integers(0, max(1, one_in // level))) == 0


# ----------------------------------------------------------------------------- measurement CSV

_GOOD_CELLS: dict[str, st.SearchStrategy[str]] = {
    "series": st.sampled_from(["I", "II"]),
    "sample": st.sampled_from(["1", "2", "3", "a"]),
    "theta_i_deg": _number_text(0.0, 89.0, odd=False),
    "theta_s_deg": _number_text(-89.0, 89.0, odd=False),
    "reflectance": _number_text(1e-6, 0.5, odd=False),
    "reflectance_err": _number_text(0.0, 1e-3, odd=False),
    "brdf": _number_text(1e-4, 10.0, odd=False),
    "brdf_err": _number_text(0.0, 1.0, odd=False),
    "phi_s_deg": st.one_of(st.just(""), _number_text(0.0, 359.0, odd=False)),
}
_ODD_CELLS: dict[str, st.SearchStrategy[str]] = {
    "series": st.sampled_from(["III", "", " I ", "i", "I;II", '"I"', "I\x00"]),
    "sample": st.sampled_from(["", "1.0", "x y", "\t"]),
    "theta_i_deg": _number_text(-90.0, 180.0),
    "theta_s_deg": _number_text(-180.0, 180.0),
    "reflectance": _number_text(-1.0, 2.0),
    "reflectance_err": _number_text(-1.0, 1.0),
    "brdf": _number_text(-1.0, 1e6),
    "brdf_err": _number_text(-1.0, 1.0),
    "phi_s_deg": _number_text(-360.0, 720.0),
}
_ENCODINGS = ["utf-8", "utf-8-sig", "latin-1", "utf-16", "cp1252", "ascii"]


@dataclass(frozen=True)
class CsvInput:
    """A measurement CSV and the scene it is read for (each series' quantity)."""

    data: bytes
    series_quantity: dict[str, str]

    def describe(self) -> str:
        return f"series {self.series_quantity}, CSV bytes {self.data[:400]!r}"


@st.composite
def measurement_csvs(draw) -> CsvInput:
    """A measurement table, well-formed or broken in one or more ways."""
    level = draw(_LEVELS)
    brdf = draw(st.booleans())
    value, error = ("brdf", "brdf_err") if brdf else ("reflectance", "reflectance_err")
    columns = ["series", "sample", "theta_i_deg", "theta_s_deg", value]
    columns += [error] if draw(st.booleans()) else []
    columns += ["phi_s_deg"] if draw(st.booleans()) else []
    columns = draw(st.permutations(columns))
    if _broken(draw, level, 6):  # a column missing, doubled, renamed, of the other quantity
        k = draw(st.integers(0, len(columns) - 1))
        columns = draw(
            st.sampled_from(
                [
                    columns[:k] + columns[k + 1 :],
                    [*columns, columns[k]],
                    [*columns[:k], columns[k].upper(), *columns[k + 1 :]],
                    [*columns, "brdf" if not brdf else "reflectance"],
                ]
            )
        )
    header = list(columns)
    if draw(st.integers(0, 3)) == 0:  # extra columns are ignored
        header.append(draw(st.sampled_from(["note", " comment ", "x y"])))
    rows, keys = [], set()
    for _ in range(draw(st.integers(1, 6)) - _broken(draw, level, 8)):
        row = []
        for name in header:
            odd = _broken(draw, level, 12)
            cells = _ODD_CELLS if odd else _GOOD_CELLS
            row.append(draw(cells.get(name, st.text(st.characters(codec="ascii"), max_size=4))))
        if _broken(draw, level, 10):  # too many or too few cells
            row = [*row, "7"] if draw(st.booleans()) else row[:-1]
        identity = ("series", "sample", "theta_i_deg", "theta_s_deg", "phi_s_deg")
        key = tuple(cell for cell, name in zip(row, header, strict=False) if name in identity)
        if key not in keys or _broken(draw, level, 2):  # duplicates only when broken
            rows.append(row)
            keys.add(key)
    if rows and _broken(draw, level, 8):
        rows.insert(draw(st.integers(0, len(rows))), list(draw(st.sampled_from(rows))))
    delimiter = draw(st.sampled_from([";", "\t", " , "])) if _broken(draw, level, 8) else ","
    quote = draw(st.integers(0, 5)) == 0  # quoted cells are fine

    def line(cells: list[str]) -> str:
        return delimiter.join(f'"{c}"' if quote else c for c in cells)

    lines = [line(header), *(line(r) for r in rows)]
    if draw(st.integers(0, 5)) == 0:  # blank lines are skipped; a comment line is a row
        blank = draw(st.sampled_from(["", "  ", "# note"] if level else ["", "  "]))
        lines.insert(draw(st.integers(1 if level == 0 else 0, len(lines))), blank)
    newline = draw(st.sampled_from(["\n", "\r\n", "\r"]))
    text = newline.join(lines) + draw(st.sampled_from([newline, "", newline * 3]))
    encoding = draw(st.sampled_from(_ENCODINGS if level else ["utf-8", "utf-8-sig"]))
    data = text.encode(encoding, errors="replace")
    if _broken(draw, level, 8):  # bytes broken: truncated, a NUL, invalid UTF-8
        cut = draw(st.integers(0, len(data)))
        data = draw(
            st.sampled_from([data[:cut], data[:cut] + b"\x00" + data[cut:], data + b"\xff"])
        )
    quantity = "brdf" if brdf else "raw_reflectance"
    other = st.sampled_from(["raw_reflectance", "brdf"])
    quantities = {
        name: quantity if not _broken(draw, level, 8) else draw(other) for name in ["I", "II"]
    }
    return CsvInput(data, quantities)


def _write_csv(folder: Path, given: CsvInput) -> Path:
    path = folder / "m.csv"
    path.write_bytes(given.data)
    return path


def _read_csv(path: Path, given: CsvInput) -> Measurements:
    """Read a generated CSV as the scene's loader does."""
    from brdf_infer.measurements import load_measurements

    return load_measurements(path, given.series_quantity, given.series_quantity)


def check_measurements(rows: Measurements, known: set[str] | None = None) -> None:
    """What a loaded table promises (the CSV loader's checks): raises AssertionError."""
    n = len(rows)
    assert n >= 1
    arrays = [rows.series, rows.sample, rows.theta_i_deg, rows.theta_s_deg, rows.reflectance]
    assert all(len(a) == n for a in arrays)
    assert all(str(s) for s in rows.series) and all(str(s) for s in rows.sample)
    assert known is None or set(rows.series.tolist()) <= known
    assert np.all(np.isfinite(rows.theta_i_deg)) and np.all(np.isfinite(rows.theta_s_deg))
    assert np.all((rows.theta_i_deg >= 0) & (rows.theta_i_deg < 90)), rows.theta_i_deg
    assert np.all(np.abs(rows.theta_s_deg) <= 90), rows.theta_s_deg
    assert np.all(np.isfinite(rows.reflectance)) and np.all(rows.reflectance > 0)
    if rows.quantity == "raw_reflectance":
        assert np.all(rows.reflectance < 1)
    if rows.reflectance_err is not None:
        assert len(rows.reflectance_err) == n
        assert np.all(np.isfinite(rows.reflectance_err)) and np.all(rows.reflectance_err >= 0)
    if rows.phi_s_deg is not None:
        phi = rows.phi_s_deg[np.isfinite(rows.phi_s_deg)]
        assert np.all((phi > 0) & (phi < 360)) and np.all(rows.theta_s_deg[rows.out_of_plane] >= 0)
    phi = np.full(n, np.nan) if rows.phi_s_deg is None else rows.phi_s_deg
    keys = {
        (s, m, t, u, "in-plane" if math.isnan(p) else p)
        for s, m, t, u, p in zip(
            rows.series, rows.sample, rows.theta_i_deg, rows.theta_s_deg, phi, strict=True
        )
    }
    assert len(keys) == n, "duplicate rows"


# ----------------------------------------------------------------------------- TOML values

_KEY_TEXT = st.text(st.characters(blacklist_categories=("Cs",)), max_size=6)


def _toml_scalars() -> st.SearchStrategy[Any]:
    return st.one_of(
        st.booleans(),
        st.integers(-(2**63), 2**63 - 1),
        st.floats(allow_nan=True, allow_infinity=True),
        st.text(st.characters(blacklist_categories=("Cs",)), max_size=8),
    )


_TOML_VALUES = st.recursive(
    _toml_scalars(),
    lambda inner: st.one_of(
        st.lists(inner, max_size=3), st.dictionaries(_KEY_TEXT, inner, max_size=3)
    ),
    max_leaves=6,
)


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        return ("-inf" if value < 0 else "inf") if math.isinf(value) else repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return (
        "{" + ", ".join(f"{_toml_value(str(k))} = {_toml_value(v)}" for k, v in value.items()) + "}"
    )


def toml_text(document: dict[str, Any], tables: bool) -> str:
    """``document`` as TOML: top-level tables as ``[name]`` sections (``tables``) or inline."""
    lines, sections = [], []
    for key, value in document.items():
        if tables and isinstance(value, dict) and value:
            sections.append(f"[{_toml_value(str(key))}]")
            sections += [f"{_toml_value(str(k))} = {_toml_value(v)}" for k, v in value.items()]
        else:
            lines.append(f"{_toml_value(str(key))} = {_toml_value(value)}")
    return "\n".join(lines + sections) + "\n"


# ----------------------------------------------------------------------------- scene TOML

_MISSING = object()


@st.composite
def _maybe(draw, plausible: st.SearchStrategy[Any], level: int, drop: int = 4) -> Any:
    """A key's value: mostly ``plausible``, with damage ``level`` sometimes any TOML value;
    absent (:data:`_MISSING`) ``drop`` times in 24."""
    wrong = (0, 1, 3, 6)[level]
    pick = draw(st.integers(0, 23))
    if pick < drop:
        return _MISSING
    return draw(_TOML_VALUES if pick < drop + wrong else plausible)


def _table_of(fields: dict[str, st.SearchStrategy[Any]], level: int, drop: int = 12):
    """A TOML table of these keys (each absent ``drop`` times in 24; with damage ``level``
    maybe of a wrong type, and maybe with an unknown key)."""

    @st.composite
    def table(draw) -> dict[str, Any]:
        content = {}
        for key, strategy in fields.items():
            value = draw(_maybe(strategy, level, drop))
            if value is not _MISSING:
                content[key] = value
        if _broken(draw, level, 12):
            content[draw(_KEY_TEXT)] = draw(_TOML_VALUES)
        return content

    return table()


def _numbers(low: float, high: float, level: int) -> st.SearchStrategy[float]:
    """A number in [low, high] (float or integer); with damage, anything."""
    good = st.one_of(st.floats(low, high), st.integers(math.ceil(low), math.floor(high)))
    if level == 0:
        return good
    odd = st.sampled_from([0.0, -1.0, 1e-300, 1e300, math.nan, math.inf, -math.inf, 0, 10**19])
    return st.integers(0, 3).flatmap(lambda pick: odd if pick == 0 else good)


def _pairs(low: float, high: float, level: int) -> st.SearchStrategy[list]:
    size = (2, 2) if level == 0 else (0, 3)
    return st.lists(_numbers(low, high, level), min_size=size[0], max_size=size[1])


def _scene_strategy(level: int) -> st.SearchStrategy[dict[str, Any]]:
    """Scene documents with damage ``level`` (0: every value plausible)."""
    from brdf_infer.error_model import (
        ANGLE_METHODS,
        CALIBRATIONS,
        ERROR_MODELS,
        LEARNED,
        ROTATION_COUPLINGS,
    )
    from brdf_infer.instrument import INSTRUMENT_MODELS, NODE_SHAPES
    from brdf_infer.model import FAMILY_NAMES
    from brdf_infer.params import PARAM_NAMES, PARAMETER_SETS, HemisphereConstants
    from brdf_infer.priors import KINDS

    def choice(good: list, bad: list) -> st.SearchStrategy[Any]:
        return st.sampled_from(good + (bad if level else []))

    def number(low: float, high: float) -> st.SearchStrategy[float]:
        return _numbers(low, high, level)

    def table(fields: dict[str, st.SearchStrategy[Any]]) -> st.SearchStrategy[dict]:
        return _table_of(fields, level)

    names = choice(["I", "II"], ["III", "bsdf", "", "I.x"])
    geometry = {
        "source_diameter_mm": number(0.5, 20),
        "source_distance_mm": number(100, 2000),
        "beam_apertures_mm": st.lists(_pairs(1, 90, level), min_size=1, max_size=3),
        "sample_size_mm": _pairs(1, 100, level),
        "detector_size_mm": _pairs(1, 100, level),
        "detector_behind_aperture_mm": number(1, 100),
        "signal_region_mm": _pairs(1, 100, level),
    }
    series = _table_of(
        {
            "aperture_diameter_mm": number(1, 20),
            "aperture_distance_mm": number(10, 200),
            "quantity": choice(["raw_reflectance"] * 5 + ["brdf"], ["BRDF", ""]),
        },
        level,
        drop=2 if level else 0,
    )
    prior = table(
        {
            "kind": choice(list(KINDS), ["gamma"]),
            "loc": number(-10, 10),
            "scale": number(0.1, 10),
            "lower": number(-100, 0),
            "upper": number(1, 100),
            "value": number(-10, 10),
        }
    )
    optional: dict[str, st.SearchStrategy[Any]] = {
        "description": st.text(max_size=10),
        "wavelength_nm": number(100, 2000),
        "errors": table(
            {
                "model": choice(list(ERROR_MODELS), ["other"]),
                "reflectance_rel": number(0, 0.5),
                "calibration": choice(list(CALIBRATIONS), ["per_row"]),
                "calibration_rel": number(0, 0.5),
                "rotation_coupling": choice(list(ROTATION_COUPLINGS), ["x"]),
                "images_per_row": st.one_of(
                    st.integers(1, 5), st.dictionaries(names, st.integers(1 - level, 5), max_size=2)
                ),
                "angle_deg": number(0, 5),
                "rotation_deg": number(0, 5),
                "camera_deg": number(0, 5),
                "propagate_angles": st.booleans(),
                "angle_method": choice(list(ANGLE_METHODS), ["exact"]),
                "hierarchical": st.booleans(),
                "sample_sd_prior": number(0.01, 5),
                "repeatability": st.one_of(st.just(LEARNED), number(0, 1)),
                "repeatability_sd_prior": number(0.01, 5),
                **({"reflectance_rel_kind": st.just("calibration")} if level else {}),
            }
        ),
        "model": table(
            {
                "fold": st.booleans(),
                "out_of_plane": st.booleans(),
                "family": choice(list(FAMILY_NAMES), ["gauss"]),
                **{name: number(-100, 100) for name in HemisphereConstants._fields},
            }
        ),
        "paper_fit": table(
            {
                "alpha": number(0.5, 10),
                "theta_s0_deg": number(-90, 90),
                "selection": choice(["paper"], ["all", "none"]),
            }
        ),
        "outputs": table(
            {
                "theta_i_deg": st.lists(number(0, 89), max_size=4),
                "tis": st.booleans(),
                "maps": st.booleans(),
                "tis_reference": choice(["ref.csv"], ["none.csv", "m.csv", ".", "ref.csv\x00"]),
                "reference_params": choice(list(PARAMETER_SETS), ["paper"]),
            }
        ),
        "priors": st.dictionaries(choice(list(PARAM_NAMES), ["beta"]), prior, max_size=3),
        "raytrace": table(
            {
                "series": names,
                "rays": st.integers(1 - level, 10**6),
                **geometry,
                "image_theta_i_deg": number(0, 89),
            }
        ),
        "instrument": table(
            {
                "model": choice(list(INSTRUMENT_MODELS), ["kernel"]),
                "nodes": st.one_of(choice(list(NODE_SHAPES), [-1, 7, [3]])),
                "candidates": st.integers(256 - level, 10**5),
                "series": st.dictionaries(names, table(geometry), max_size=2),
            }
        ),
        "studies": table(
            {
                "error_models": st.lists(choice(list(ERROR_MODELS), ["x"]), max_size=2),
                "instruments": st.lists(choice(list(INSTRUMENT_MODELS), ["x"]), max_size=2),
                "raytrace": st.booleans(),
                "compare": st.lists(choice(list(FAMILY_NAMES), ["x"]), max_size=3),
                "sensitivity": st.booleans(),
            }
        ),
        "compare": st.lists(choice(list(FAMILY_NAMES), ["x"]), max_size=3),
        "bsdf": table(
            {
                "keep_every_radial": st.integers(1 - level, 4),
                "keep_every_azimuth": st.integers(1 - level, 4),
            }
        ),
    }
    required = {
        "name": choice(
            ["tiny", "a b", "ü", "lya-2"], ["", " ", ".", "..", "a/b", "../up", "x\x00"]
        ),
        "measurements": choice(
            ["m.csv", "m.csv", "m.csv", "t.BSDF"],
            [
                "none.csv",
                ".",
                "",
                "m.csv\x00x",
                "../m.csv",
                "/",
                "sub/m.csv",
                "x" * 300 + ".csv",
                "m.CSV",
                "t.bsdf",
            ],
        ),
        "series": (
            st.dictionaries(names, series, max_size=3)
            if level
            else st.fixed_dictionaries({"I": series, "II": series})
        ),
    }

    @st.composite
    def documents(draw) -> dict[str, Any]:
        document = {}
        for key, strategy in required.items():
            value = draw(_maybe(strategy, level, drop=1 if level else 0))
            if value is not _MISSING:
                document[key] = value
        if level == 0 and document["measurements"] == "t.BSDF":  # one series, or none
            document["series"] = {"bsdf": {"quantity": "brdf"}}
            if draw(st.booleans()):
                del document["series"]
        for key in draw(st.lists(st.sampled_from(sorted(optional)), max_size=4, unique=True)):
            document[key] = draw(optional[key])
        if _broken(draw, level, 15):
            document[draw(_KEY_TEXT)] = draw(_TOML_VALUES)
        return document

    return documents()


_SCENES = {}


def _scenes(level: int) -> st.SearchStrategy[dict[str, Any]]:
    """:func:`_scene_strategy` of ``level``, built once."""
    if level not in _SCENES:
        _SCENES[level] = _scene_strategy(level)
    return _SCENES[level]


_GOOD_CSV = (
    "series,sample,theta_i_deg,theta_s_deg,reflectance,reflectance_err\n"
    "I,1,18,18,5.79e-05,3.3e-06\nI,1,45,45,8.46e-05,5.7e-06\nI,2,80,80,1.15e-03,9.0e-05\n"
    "II,1,45,50,8.0e-05,5.0e-06\nII,2,60,70,2.0e-04,1.0e-05\n"
)
_GOOD_REFERENCE = "theta_i_deg,tis,label\n70,0.06,paper\n"


@dataclass(frozen=True)
class SceneInput:
    """A scene TOML (text, or broken bytes) and the files beside it."""

    data: bytes
    files: dict[str, bytes]

    def describe(self) -> str:
        return f"scene {self.data[:1500]!r}; files {sorted(self.files)}"


@st.composite
def scene_files(draw) -> SceneInput:
    """A scene, well-formed or broken in one or more ways, with the files it may name."""
    level = draw(_LEVELS)
    document = draw(_scenes(level))
    text = toml_text(document, tables=draw(st.booleans()))
    data = text.encode()
    if _broken(draw, level, 8):  # broken bytes: truncated, a BOM, a doubled line
        cut = draw(st.integers(0, len(data)))
        lines = text.splitlines(keepends=True)
        data = draw(
            st.sampled_from(
                [data[:cut], b"\xef\xbb\xbf" + data, (text + (lines[0] if lines else "")).encode()]
            )
        )
    files = {"m.csv": _GOOD_CSV.encode(), "ref.csv": _GOOD_REFERENCE.encode()}
    if _broken(draw, level, 4):
        files["m.csv"] = draw(measurement_csvs()).data
    files["t.BSDF"] = draw(bsdf_files()).data
    return SceneInput(data, files)


def _write_scene(folder: Path, given: SceneInput) -> Path:
    for name, data in given.files.items():
        (folder / name).write_bytes(data)
    path = folder / "scene.toml"
    path.write_bytes(given.data)
    return path


def _read_scene(path: Path, given: SceneInput):
    """Load a generated scene (every file it names checked) as the command line does."""
    from brdf_infer.scene import load_scene

    return load_scene(str(path))


def check_scene(scene) -> None:
    """What a loaded scene promises: its rows, and its series known."""
    rows = scene.load_measurements()
    check_measurements(rows, set(scene.series))
    assert scene.name and isinstance(scene.name, str)


# ----------------------------------------------------------------------------- Zemax .BSDF

_HEADER_VALUES = {
    "Source": ["Measured", "Unknown", "Measured data", ""],
    "Symmetry": ["PlaneSymmetrical", "Asymmetrical", "Asymmetrical4D", "plane"],
    "SpectralContent": ["Monochrome", "Tristimulus", "Spectral"],
    "ScatterType": ["BRDF", "BTDF", "BSDF"],
}


@dataclass(frozen=True)
class BsdfInput:
    """A tabular .BSDF file and the thinning the scene asks for."""

    data: bytes
    keep_every_radial: int
    keep_every_azimuth: int

    def describe(self) -> str:
        return f"thinning {self.keep_every_radial}, {self.keep_every_azimuth}; {self.data[:1500]!r}"


@st.composite
def bsdf_files(draw) -> BsdfInput:
    """A Zemax tabular .BSDF file, well-formed or broken in one or more ways."""
    level = draw(_LEVELS)
    sep = draw(st.sampled_from([" ", "\t", "  ", " \t "]))  # any run of blanks separates
    header = [
        f"{key}{sep}{draw(st.sampled_from(values if _broken(draw, level, 6) else values[:1]))}"
        for key, values in _HEADER_VALUES.items()
    ]
    counts = {
        "SampleRotation": draw(st.integers(1, 2)),
        "AngleOfIncidence": draw(st.integers(1, 3)),
        "ScatterAzimuth": draw(st.integers(1, 4)),
        "ScatterRadial": draw(st.integers(1, 4)),
    }
    ranges = {
        "SampleRotation": (0.0, 360.0),
        "AngleOfIncidence": (0.0, 89.0),
        "ScatterAzimuth": (0.0, 360.0),
        "ScatterRadial": (0.0, 90.0),
    }
    for key, count in counts.items():
        if _broken(draw, level, 6):
            values = [draw(_number_text(-100.0, 400.0)) for _ in range(count)]
        else:
            values = [f"{v:g}" for v in np.linspace(*ranges[key], count, endpoint=False)]
        declared = draw(st.integers(-1, 6)) if _broken(draw, level, 8) else count
        header += [f"{key}{sep}{declared}", sep.join(values)]
    header += [
        draw(st.sampled_from(["Tristimulus", "Spectral"]))
        if _broken(draw, level, 8)
        else "Monochrome",
        "DataBegin",
    ]
    if _broken(draw, level, 6):  # two header lines swapped
        i, j = (draw(st.integers(0, len(header) - 1)) for _ in range(2))
        header[i], header[j] = header[j], header[i]
    body = []
    for _ in range(counts["SampleRotation"]):
        for _ in range(counts["AngleOfIncidence"]):
            body.append(f"TIS{sep}{draw(_number_text(0.0, 1.0, _broken(draw, level, 8)))}")
            for _ in range(counts["ScatterAzimuth"]):
                width = counts["ScatterRadial"] + _broken(draw, level, 10)
                odd = _broken(draw, level, 6)
                body.append(sep.join(draw(_number_text(0.0, 5.0, odd)) for _ in range(width)))
    lines = [f"# generated{sep}file", *header, *body, "DataEnd"]
    if draw(st.integers(0, 5)) == 0:  # blank and comment lines anywhere
        lines.insert(draw(st.integers(0, len(lines))), draw(st.sampled_from(["", "# x", "\t"])))
    newline = draw(st.sampled_from(["\n", "\r\n"]))
    encoding = draw(st.sampled_from(["utf-8", "utf-16", "latin-1"])) if level else "utf-8"
    data = (newline.join(lines) + newline).encode(encoding, errors="replace")
    if _broken(draw, level, 6):  # truncated, or a stray byte
        cut = draw(st.integers(0, len(data)))
        data = draw(st.sampled_from([data[:cut], data[:cut] + b"\xfe" + data[cut:]]))
    return BsdfInput(data, draw(st.integers(1, 3)), draw(st.integers(1, 3)))


def _write_bsdf(folder: Path, given: BsdfInput) -> Path:
    path = folder / "t.BSDF"
    path.write_bytes(given.data)
    return path


def _read_bsdf(path: Path, given: BsdfInput) -> Measurements:
    """Read a generated .BSDF file as a scene's measurements (``export --check`` reads it
    with the same reader)."""
    from brdf_infer.bsdf_measurements import measurements_from_bsdf

    return measurements_from_bsdf(path, given.keep_every_radial, given.keep_every_azimuth)


# ----------------------------------------------------------------------------- parameter JSON

_JSON_SCALARS = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**400), 10**400),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=6),
)
_JSON_VALUES = st.recursive(
    _JSON_SCALARS,
    lambda inner: st.one_of(
        st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=5), inner, max_size=3)
    ),
    max_leaves=6,
)


@dataclass(frozen=True)
class ParamsInput:
    """``--params``: a name, an inline JSON object, or a JSON file (``data``)."""

    argument: str
    data: bytes | None

    def describe(self) -> str:
        data = None if self.data is None else self.data[:800]
        return f"--params {self.argument[:300]!r}; file {data!r}"


@st.composite
def parameter_inputs(draw) -> ParamsInput:
    """A parameter set: the six fields, well-formed or with wrong types, odd numbers, odd
    nesting, broken text."""
    from brdf_infer.params import PARAM_NAMES, UV_PAPER

    level = draw(_LEVELS)
    fields: dict[str, Any] = {}
    for name, good in zip(PARAM_NAMES, UV_PAPER, strict=True):
        plausible = st.floats(0.5 * good, 2 * good) if good > 0 else st.floats(2 * good, 0.5 * good)
        value = draw(_JSON_VALUES if _broken(draw, level, 4) else plausible)
        if not _broken(draw, level, 12):
            fields[name] = value
    if draw(st.integers(0, 3)) == 0:  # extra keys are ignored
        fields["sigma"] = {"brdf0": 1e-3}
    shapes = ["flat", "params", "fit"] + (["list", "any", "deep"] if level else [])
    content = {
        "flat": lambda: fields,
        "params": lambda: {"params": fields},
        "fit": lambda: {"method": "lsq", "params": fields, "cost": 3.0},
        "list": lambda: [fields],
        "any": lambda: draw(_JSON_VALUES),
        "deep": lambda: json.loads("[" * 50 + "]" * 50),
    }[draw(st.sampled_from(shapes))]()
    text = json.dumps(content, allow_nan=True, indent=draw(st.sampled_from([None, 2, "\t"])))
    if _broken(draw, level, 6):  # nesting deeper than a parser's stack, or broken text
        text = draw(st.sampled_from(["[" * 100_000 + "]" * 100_000, text[: len(text) // 2], "{"]))
    how = draw(st.sampled_from(["file", "file", "inline", "name"]))
    if how == "name":
        names = ["uv-paper", "vis-paper"] + (["UV-paper", "", "p.json\x00"] if level else [])
        return ParamsInput(draw(st.sampled_from(names)), None)
    if how == "inline":
        return ParamsInput(text if text.lstrip().startswith("{") else "{" + text, None)
    encodings = ["utf-8", "utf-8-sig"] + (["utf-16", "latin-1"] if level else [])
    return ParamsInput("p.json", text.encode(draw(st.sampled_from(encodings)), errors="replace"))


def _write_params(folder: Path, given: ParamsInput) -> str:
    if given.data is None:
        return given.argument
    (folder / given.argument).write_bytes(given.data)
    return str(folder / given.argument)


def _read_params(argument: str, given: ParamsInput):
    """Resolve a generated ``--params`` as the command line does."""
    from brdf_infer.params import resolve_params

    return resolve_params(argument)


def check_params(params) -> None:
    """Six finite numbers, BRDF0 > 0."""
    values = np.asarray([float(v) for v in params])
    assert values.shape == (6,) and np.all(np.isfinite(values)) and values[0] > 0


# ----------------------------------------------------------------------------- command lines


def _scene_for_rows(path: Path, measurements: str, series: dict[str, str], extra: str = "") -> str:
    """A scene file beside ``path`` that reads it; its path."""
    tables = []
    for name, quantity in series.items():
        aperture = (
            "aperture_diameter_mm = 7.2\naperture_distance_mm = 103.8\n"
            if quantity == "raw_reflectance"
            else ""
        )
        tables.append(f'[series.{name}]\n{aperture}quantity = "{quantity}"\n')
    scene = path.parent / "reads.toml"
    scene.write_text(f'name = "reads"\nmeasurements = "{measurements}"\n{extra}' + "".join(tables))
    return str(scene)


def _csv_command(path: Path, given: CsvInput) -> list[str]:
    return ["fit", _scene_for_rows(path, path.name, given.series_quantity), "--method", "paper"]


def _bsdf_command(path: Path, given: BsdfInput) -> list[str]:
    thinning = (
        f"[bsdf]\nkeep_every_radial = {given.keep_every_radial}\n"
        f"keep_every_azimuth = {given.keep_every_azimuth}\n"
    )
    scene = _scene_for_rows(path, path.name, {}, thinning)
    return ["fit", scene, "--method", "paper"]


def _params_command(argument: str, given: ParamsInput) -> list[str] | None:
    if given.data is None and not argument.lstrip().startswith("{"):
        return None  # a name: the command line reads an empty one as the default
    return ["tis", "--params", argument, "--theta-i", "70"]


# ----------------------------------------------------------------------------- the check


@dataclass(frozen=True)
class Loader:
    """A loader under test: its inputs, how to put one in a folder (the path or argument the
    loader is given), how to read it, what its result promises."""

    name: str
    inputs: Callable[[], st.SearchStrategy[Any]]
    prepare: Callable[[Path, Any], Any]
    read: Callable[[Any, Any], Any]
    check: Callable[[Any], None]
    command: Callable[[Any, Any], list[str] | None]  # brdf-infer arguments that read it


LOADERS: dict[str, Loader] = {
    loader.name: loader
    for loader in (
        Loader(
            "measurement CSV",
            measurement_csvs,
            _write_csv,
            _read_csv,
            lambda rows: check_measurements(rows, {"I", "II"}),
            _csv_command,
        ),
        Loader(
            "scene TOML",
            scene_files,
            _write_scene,
            _read_scene,
            check_scene,
            lambda path, given: ["fit", str(path), "--method", "paper"],
        ),
        Loader(
            "Zemax .BSDF", bsdf_files, _write_bsdf, _read_bsdf, check_measurements, _bsdf_command
        ),
        Loader(
            "parameter JSON",
            parameter_inputs,
            _write_params,
            _read_params,
            check_params,
            _params_command,
        ),
    )
}


def _listing(folder: Path) -> dict[str, int]:
    return {str(p.relative_to(folder)): p.stat().st_size for p in folder.rglob("*")}


def run_loader(
    loader: Loader, given: Any, refused: Callable[[list[str], str], None] | None = None
) -> BadInputError | None:
    """Load ``given`` in a fresh folder: None for a result that holds what the loader
    promises, the error for a refusal (one line, naming a file or an option). ``refused``
    is called with the loader's command line and the refusal's message (in the folder, before
    it goes).

    Raises:
        AssertionError: a result that breaks its promises, a message of several lines, a
            refusal naming neither file nor option, or a file written or removed.
        Exception: any error other than BadInputError (a traceback on the command line).
    """
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        target = loader.prepare(folder, given)
        before = _listing(folder)
        try:
            result = loader.read(target, given)
        except BadInputError as error:
            message = str(error)
            assert message and "\n" not in message and "\r" not in message, repr(message)
            assert error.file is not None or error.field is not None, message
            assert _listing(folder) == before, "the loader wrote a file"
            argv = loader.command(target, given)
            if refused is not None and argv is not None:
                refused(argv, message)
            return error
        assert _listing(folder) == before, "the loader wrote a file"
        loader.check(result)
        return None
