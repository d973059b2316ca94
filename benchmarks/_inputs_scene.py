"""Generated scene TOML files (every table and key) with the files they may name, and what a
loaded scene promises."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hypothesis import strategies as st

from benchmarks._inputs import _KEY_TEXT, _LEVELS, _TOML_VALUES, _broken, toml_text
from benchmarks._inputs_bsdf import bsdf_files
from benchmarks._inputs_csv import check_measurements, measurement_csvs

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


@dataclass(frozen=True)
class _Values:
    """Strategies of a scene's values with damage ``level`` (0: every value plausible)."""

    level: int

    def choice(self, good: list, bad: list) -> st.SearchStrategy[Any]:
        return st.sampled_from(good + (bad if self.level else []))

    def number(self, low: float, high: float) -> st.SearchStrategy[float]:
        return _numbers(low, high, self.level)

    def table(self, fields: dict[str, st.SearchStrategy[Any]]) -> st.SearchStrategy[dict]:
        return _table_of(fields, self.level)

    def names(self) -> st.SearchStrategy[str]:
        """Series names."""
        return self.choice(["I", "II"], ["III", "bsdf", "", "I.x"])


def _geometry(values: _Values) -> dict[str, st.SearchStrategy[Any]]:
    """The lengths of a setup [mm] (``[raytrace]``, ``[instrument.series.NAME]``)."""
    level, number = values.level, values.number
    return {
        "source_diameter_mm": number(0.5, 20),
        "source_distance_mm": number(100, 2000),
        "beam_apertures_mm": st.lists(_pairs(1, 90, level), min_size=1, max_size=3),
        "sample_size_mm": _pairs(1, 100, level),
        "detector_size_mm": _pairs(1, 100, level),
        "detector_behind_aperture_mm": number(1, 100),
        "signal_region_mm": _pairs(1, 100, level),
    }


def _errors_table(values: _Values) -> st.SearchStrategy[dict]:
    """The ``[errors]`` table."""
    from brdf_infer.model.error_model import (
        ANGLE_METHODS,
        CALIBRATIONS,
        ERROR_MODELS,
        LEARNED,
        ROTATION_COUPLINGS,
    )

    level, choice, number, table = values.level, values.choice, values.number, values.table
    names = values.names()
    return table(
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
    )


def _model_tables(values: _Values) -> dict[str, st.SearchStrategy[Any]]:
    """The optional keys of the model and its fit: description, wavelength, ``[errors]``,
    ``[model]``, ``[paper_fit]``, ``[outputs]`` and ``[priors]``."""
    from brdf_infer.model import FAMILY_NAMES
    from brdf_infer.model.params import PARAM_NAMES, PARAMETER_SETS, HemisphereConstants
    from brdf_infer.model.priors import KINDS

    choice, number, table = values.choice, values.number, values.table
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
    return {
        "description": st.text(max_size=10),
        "wavelength_nm": number(100, 2000),
        "errors": _errors_table(values),
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
    }


def _study_tables(values: _Values) -> dict[str, st.SearchStrategy[Any]]:
    """The optional tables of the instrument and the studies: ``[raytrace]``,
    ``[instrument]``, ``[studies]``, ``compare`` and ``[bsdf]``."""
    from brdf_infer.instrument import INSTRUMENT_MODELS, NODE_SHAPES
    from brdf_infer.model import FAMILY_NAMES
    from brdf_infer.model.error_model import ERROR_MODELS

    level, choice, number, table = values.level, values.choice, values.number, values.table
    names, geometry = values.names(), _geometry(values)
    return {
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


def _required_keys(values: _Values) -> dict[str, st.SearchStrategy[Any]]:
    """The keys every scene has: ``name``, ``measurements`` and ``[series.NAME]`` tables."""
    level, choice, number = values.level, values.choice, values.number
    series = _table_of(
        {
            "aperture_diameter_mm": number(1, 20),
            "aperture_distance_mm": number(10, 200),
            "quantity": choice(["raw_reflectance"] * 5 + ["brdf"], ["BRDF", ""]),
        },
        level,
        drop=2 if level else 0,
    )
    return {
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
            st.dictionaries(values.names(), series, max_size=3)
            if level
            else st.fixed_dictionaries({"I": series, "II": series})
        ),
    }


def _scene_strategy(level: int) -> st.SearchStrategy[dict[str, Any]]:
    """Scene documents with damage ``level`` (0: every value plausible)."""
    values = _Values(level)
    required = _required_keys(values)
    optional = {**_model_tables(values), **_study_tables(values)}

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
