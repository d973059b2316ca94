"""Readers of the scene's analysis tables: ``[model] family``, ``[paper_fit] selection``,
``name``, ``[studies]``, ``[design]`` and ``[reference]``."""

from __future__ import annotations

import math
from pathlib import Path

from brdf_infer.errors import BadInputError
from brdf_infer.scene._fields import (
    _angle_range,
    _boolean,
    _names,
    _number,
    _string,
    _table,
)
from brdf_infer.scene._records import DesignSettings, ReferenceValue, Studies, tis_angle_deg
from brdf_infer.tables.selections import SELECTIONS


def _model_family(model: dict, path: Path) -> str:
    """``[model] family``, one of the model families (default ``strumik2024``)."""
    from brdf_infer.model import check_family_name

    name = model.get("family", "strumik2024")
    check_family_name(name, file=path, field="model.family")
    return name


def _compare_families(names, path: Path, field_name: str) -> tuple[str, ...]:
    """Model families to compare by PSIS-LOO (at least two; none: no comparison)."""
    from brdf_infer.model import FAMILY_NAMES

    names = _names(names, path, field_name, FAMILY_NAMES, "model family")
    if len(names) == 1:
        raise BadInputError("name at least two families to compare", file=path, field=field_name)
    return names


def _parse_studies(document: dict, path: Path) -> Studies:
    """The ``[studies]`` table (and the older top-level ``compare = [...]``)."""
    from brdf_infer.instrument import INSTRUMENT_MODELS
    from brdf_infer.model.error_model import ERROR_MODELS

    table = _table(document, "studies", path, set(Studies.__dataclass_fields__))
    if "compare" in document and "compare" in table:
        raise BadInputError(
            "give compare once: in [studies] (the top-level key is its older form)",
            file=path,
            field="studies.compare",
        )
    compare = table.get("compare", document.get("compare", []))
    field_name = "studies.compare" if "compare" in table else "compare"
    return Studies(
        error_models=_names(
            table.get("error_models", []),
            path,
            "studies.error_models",
            ERROR_MODELS,
            "error model",
        ),
        instruments=_names(
            table.get("instruments", []),
            path,
            "studies.instruments",
            INSTRUMENT_MODELS,
            "instrument model",
        ),
        raytrace=_boolean(table, "raytrace", path, "studies.", False),
        compare=_compare_families(compare, path, field_name),
        sensitivity=_boolean(table, "sensitivity", path, "studies.", False),
        design=_design_target(table, path),
    )


def _design_target(table: dict, path: Path) -> str | None:
    from brdf_infer.scene.design_target import parse_target

    if "design" not in table:
        return None
    parse_target(table["design"], field="studies.design", file=path)
    return table["design"].strip()


def _parse_design(document: dict, path: Path, series: dict) -> DesignSettings:
    """The ``[design]`` table (:class:`DesignSettings`)."""
    table = _table(document, "design", path, set(DesignSettings.__dataclass_fields__))
    defaults = DesignSettings()
    for key in ("series", "same_session"):
        name = table.get(key)
        if name is not None and name not in series:
            raise BadInputError(
                f"no series {name!r} in the scene (known: {', '.join(series)})",
                file=path,
                field=f"design.{key}",
            )
    clearance = _number(table, "source_clearance_deg", path, default=defaults.source_clearance_deg)
    if not 0.0 <= clearance < 90.0:
        raise BadInputError(
            f"expected an angle in [0, 90) deg, got {clearance:g}",
            file=path,
            field="design.source_clearance_deg",
        )
    try:
        step = _number(table, "step_deg", path, default=defaults.step_deg, positive=True)
    except BadInputError as error:
        raise BadInputError(error.problem, file=path, field="design.step_deg") from None
    budget = table.get("budget", defaults.budget)
    if isinstance(budget, bool) or not isinstance(budget, int) or not 1 <= budget <= 10:
        raise BadInputError(
            f"expected an integer in [1, 10], got {budget!r}", file=path, field="design.budget"
        )
    return DesignSettings(
        theta_i_deg=_angle_range(table, "theta_i_deg", path, defaults.theta_i_deg, 0.0, 89.0),
        theta_s_deg=_angle_range(table, "theta_s_deg", path, defaults.theta_s_deg, -89.0, 89.0),
        step_deg=step,
        source_clearance_deg=clearance,
        series=table.get("series"),
        same_session=table.get("same_session"),
        budget=budget,
    )


def _scene_name(document: dict, path: Path) -> str:
    """``name``: it names the scene's results folder (``reports/<name>``, a batch's
    ``OUT/<name>``), so it is a plain folder name."""
    name = _string(document, "name", path)
    if not name.strip() or name in (".", "..") or any(c in name for c in "/\\\x00"):
        raise BadInputError(
            f"expected a non-empty name without '/', got {name!r} (it names the results folder)",
            file=path,
            field="name",
        )
    return name


def _selection(paper: dict, path: Path) -> str:
    """``[paper_fit] selection``: a name of :data:`brdf_infer.tables.selections.SELECTIONS`."""
    name = _string(paper, "selection", path, default="paper")
    if name not in SELECTIONS:
        raise BadInputError(
            f"unknown selection {name!r} (known: {', '.join(SELECTIONS)})",
            file=path,
            field="paper_fit.selection",
        )
    return name


def reference_quantity_ok(quantity: str) -> bool:
    """Whether a ``[reference]`` quantity names something a run reports: ``tis_<θi>deg``
    with 0 ≤ θi < 90, ``pi_brdf0`` or a parameter of Eq. (7)."""
    from brdf_infer.model.params import PARAM_NAMES

    angle = tis_angle_deg(quantity)
    if angle is not None:
        return angle < 90.0
    return quantity == "pi_brdf0" or quantity in PARAM_NAMES


def _parse_references(document: dict, path: Path) -> tuple[ReferenceValue, ...]:
    """The ``[reference.QUANTITY]`` tables: published values with their source."""
    table = document.get("reference", {})
    if not isinstance(table, dict):
        raise BadInputError("expected a table [reference]", file=path, field="reference")
    references = []
    for quantity, entry in table.items():
        field_name = f"reference.{quantity}"
        if not reference_quantity_ok(quantity):
            raise BadInputError(
                "unknown quantity (tis_<angle>deg, pi_brdf0 or a parameter of Eq. 7)",
                file=path,
                field=field_name,
            )
        entry = _table(table, quantity, path, {"value", "source"}, parent="reference.")
        value = _number(entry, "value", path)
        if not math.isfinite(value):
            raise BadInputError("expected a finite number", file=path, field=field_name + ".value")
        source = entry.get("source")
        if not isinstance(source, str) or not source.strip():
            raise BadInputError(
                "missing: where the value comes from", file=path, field=field_name + ".source"
            )
        references.append(ReferenceValue(quantity, value, source.strip()))
    return tuple(references)
