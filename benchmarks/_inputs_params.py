"""Generated parameter sets for ``--params``: a name, an inline JSON object or a JSON file."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import strategies as st

from benchmarks._inputs import _LEVELS, _broken

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
    from brdf_infer.model.params import PARAM_NAMES, UV_PAPER

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
    from brdf_infer.model.params import resolve_params

    return resolve_params(argument)


def check_params(params) -> None:
    """Six finite numbers, BRDF0 > 0."""
    values = np.asarray([float(v) for v in params])
    assert values.shape == (6,) and np.all(np.isfinite(values)) and values[0] > 0


def _params_command(argument: str, given: ParamsInput) -> list[str] | None:
    if given.data is None and not argument.lstrip().startswith("{"):
        return None  # a name: the command line reads an empty one as the default
    return ["tis", "--params", argument, "--theta-i", "70"]
