"""Parameters of the in-plane BRDF model, Eq. (7), and the constants of Eqs. (8) and (10).

All public parameters are in the paper's units: ``brdf0`` [sr⁻¹], ``a1`` [deg⁻²],
``a2`` [deg^(−1−α)], ``a3`` [deg^(−2−α)], ``alpha`` [-], ``theta_s0`` [deg].
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any, NamedTuple

from brdf_infer._internal.resources import read_data_toml
from brdf_infer.errors import BadInputError
from brdf_infer.runs.folder import read_json_file

PARAM_NAMES: tuple[str, ...] = ("brdf0", "a1", "a2", "a3", "alpha", "theta_s0")


class Params(NamedTuple):
    """Parameters of Eq. (7) in paper units; a JAX pytree (fields may be arrays of draws).

    Attributes:
        brdf0: BRDF plateau below ``theta_s0`` [sr⁻¹].
        a1: linear coefficient [deg⁻²].
        a2: power-law coefficient [deg^(−1−α)].
        a3: power-law coefficient [deg^(−2−α)].
        alpha: power-law exponent [-].
        theta_s0: scattering angle below which the BRDF is constant [deg].
    """

    brdf0: Any
    a1: Any
    a2: Any
    a3: Any
    alpha: Any
    theta_s0: Any


class HemisphereConstants(NamedTuple):
    """Fixed constants of the full-hemisphere extension (Sec. 5.2).

    Attributes:
        c1: slope of the azimuthal half-width Δφ = c1·θi + c2 of Eq. (8) [-].
        c2_deg: offset of Δφ [deg].
        fold_a_per_deg: steepness ``a`` of the folding term, Eq. (10) [deg⁻¹].
        fold_theta_sf_deg: folding angle θsf of Eq. (10) [deg].
    """

    c1: Any
    c2_deg: Any
    fold_a_per_deg: Any
    fold_theta_sf_deg: Any


DPHI_NAME = "dphi_scale"  # Δφ's factor on the article's c1, c2 (a parameter where uncertain)


def with_dphi_scale(constants: HemisphereConstants, scale: Any) -> HemisphereConstants:
    """``constants`` with Eq. (8)'s half-width Δφ = c1·θi + c2 multiplied by ``scale`` [-]
    (c1 and c2 both: the shape of Δφ(θi) kept, its size scaled); ``scale`` may be an array
    (one per draw), which every function taking the constants broadcasts like the parameters'
    fields."""
    return constants._replace(c1=constants.c1 * scale, c2_deg=constants.c2_deg * scale)


def _load_constants() -> HemisphereConstants:
    table = read_data_toml("paper_constants.toml")
    return HemisphereConstants(
        c1=float(table["out_of_plane"]["c1"]),
        c2_deg=float(table["out_of_plane"]["c2_deg"]),
        fold_a_per_deg=float(table["folding"]["a_per_deg"]),
        fold_theta_sf_deg=float(table["folding"]["theta_sf_deg"]),
    )


def _load_parameter_sets() -> dict[str, Params]:
    table = read_data_toml("parameter_sets.toml")
    return {name: Params(*(float(entry[f]) for f in PARAM_NAMES)) for name, entry in table.items()}


PAPER_CONSTANTS: HemisphereConstants = _load_constants()
PARAMETER_SETS: dict[str, Params] = _load_parameter_sets()
UV_PAPER: Params = PARAMETER_SETS["uv-paper"]
VIS_PAPER: Params = PARAMETER_SETS["vis-paper"]


def params_to_dict(params: Params) -> dict[str, float]:
    """Six plain floats keyed by the ``Params`` field names (the JSON contract)."""
    return {name: float(value) for name, value in zip(PARAM_NAMES, params, strict=True)}


_LARGEST_INTEGER = int(sys.float_info.max)


def _short(value: Any) -> str:
    """``repr(value)``, cut to 60 characters."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def params_from_mapping(mapping: Any, *, source: str = "parameters") -> Params:
    """Build ``Params`` from a mapping with the six field names, validating every value.

    Args:
        mapping: a dict with keys ``brdf0, a1, a2, a3, alpha, theta_s0`` (extra keys ignored).
        source: where the mapping came from, for error messages.

    Raises:
        BadInputError: a field is missing, not a finite number, or outside its domain
            (``brdf0`` must be > 0).
    """
    if not isinstance(mapping, dict):
        raise BadInputError("expected an object with the six parameter fields", file=source)
    values = {}
    for name in PARAM_NAMES:
        if name not in mapping:
            raise BadInputError("missing parameter", file=source, field=name)
        value = mapping[name]
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise BadInputError(f"not a number: {_short(value)}", file=source, field=name)
        if isinstance(value, int) and abs(value) > _LARGEST_INTEGER:  # float() would overflow
            raise BadInputError(f"not finite: {_short(value)}", file=source, field=name)
        if not math.isfinite(value):
            raise BadInputError(f"not finite: {value!r}", file=source, field=name)
        values[name] = float(value)
    if values["brdf0"] <= 0:
        raise BadInputError(f"must be > 0, got {values['brdf0']}", file=source, field="brdf0")
    return Params(**values)


def resolve_params(name_or_file: str) -> Params:
    """A named parameter set (``uv-paper``, ``vis-paper``), an inline JSON object or a JSON file
    of the six fields.

    A JSON file may hold the fields at its top level or under ``"params"`` (the output of
    ``brdf-infer fit --json`` can be used directly).

    Raises:
        BadInputError: unknown name, unreadable or malformed file, bad field.
    """
    if name_or_file in PARAMETER_SETS:
        return PARAMETER_SETS[name_or_file]
    if name_or_file.lstrip().startswith("{"):
        try:
            content = json.loads(name_or_file)
        except json.JSONDecodeError as error:
            raise BadInputError(f"not valid JSON: {error.msg}", field="params") from None
        except RecursionError:
            raise BadInputError("not valid JSON: nested too deeply", field="params") from None
        return params_from_mapping(content, source="--params")
    path = Path(name_or_file)
    if not path.exists():
        known = ", ".join(sorted(PARAMETER_SETS))
        raise BadInputError(
            f"neither a parameter set ({known}) nor an existing JSON file", file=name_or_file
        )
    content = read_json_file(path, encoding="utf-8-sig")  # BadInputError naming the file
    if isinstance(content, dict) and isinstance(content.get("params"), dict):
        content = content["params"]
    return params_from_mapping(content, source=str(path))
