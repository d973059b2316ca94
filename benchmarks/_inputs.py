"""What the generated inputs of :mod:`._loader_inputs` are made of: numbers as text (well-formed
and odd), the level of damage each input is drawn with, TOML values and text, and a scene that
reads a generated table."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from hypothesis import strategies as st

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
