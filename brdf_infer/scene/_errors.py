"""The ``[errors]`` table of a scene (:class:`brdf_infer.model.error_model.ErrorSettings`)."""

from __future__ import annotations

from pathlib import Path

from brdf_infer.errors import BadInputError
from brdf_infer.model.error_model import (
    ANGLE_METHODS,
    CALIBRATIONS,
    ERROR_MODELS,
    LEARNED,
    ROTATION_COUPLINGS,
    ErrorSettings,
)
from brdf_infer.scene._fields import _boolean, _choice, _prefixed_number, _table

_REPLACED_ERROR_KEYS = {
    "reflectance_rel_kind": 'replaced by errors.calibration = "per_series" | "per_sample" | '
    '"none" and errors.calibration_rel (the old "calibration" kind is calibration = '
    '"per_series" with calibration_rel = the old reflectance_rel; "per_row" is calibration = '
    '"none"; README, "Error model")',
}


def _images_per_row(table: dict, path: Path, series: tuple[str, ...]) -> int | dict[str, int]:
    """``errors.images_per_row``: a positive integer, or a table series name → integer."""

    def count(value, field: str) -> int:
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise BadInputError(
                f"expected a positive integer, got {value!r}", file=path, field=field
            )
        return value

    value = table.get("images_per_row", ErrorSettings().images_per_row)
    if not isinstance(value, dict):
        return count(value, "errors.images_per_row")
    for name in value:
        if name not in series:
            raise BadInputError(
                f"no series {name!r} in the scene (series: {', '.join(series)})",
                file=path,
                field=f"errors.images_per_row.{name}",
            )
    return {name: count(n, f"errors.images_per_row.{name}") for name, n in value.items()}


def parse_errors(table: dict, path: Path, series: tuple[str, ...]) -> ErrorSettings:
    """The ``[errors]`` table (schema: :class:`brdf_infer.model.error_model.ErrorSettings`) of a
    scene with these ``series``.

    Raises:
        BadInputError: an unknown or replaced key, or a value out of range (naming the field).
    """
    defaults = ErrorSettings()
    for key, replacement in _REPLACED_ERROR_KEYS.items():
        if key in table:
            raise BadInputError(replacement, file=path, field="errors." + key)
    table = _table({"errors": table}, "errors", path, set(ErrorSettings.__dataclass_fields__))

    def number(key: str, default: float, *, positive: bool = False) -> float:
        value = _prefixed_number(table, key, path, default, "errors.", positive=False)
        if value < 0 or (positive and value == 0):
            bound = "> 0" if positive else ">= 0"
            raise BadInputError(f"must be {bound}, got {value:g}", file=path, field="errors." + key)
        return value

    repeatability = table.get("repeatability", defaults.repeatability)
    if isinstance(repeatability, str) and repeatability != LEARNED:
        raise BadInputError(
            f'expected "{LEARNED}" or a number >= 0, got {repeatability!r}',
            file=path,
            field="errors.repeatability",
        )
    if repeatability != LEARNED:
        repeatability = number("repeatability", 0.0)
    angle = number("angle_deg", defaults.angle_deg)
    reflectance_rel = number("reflectance_rel", defaults.reflectance_rel)
    return ErrorSettings(
        model=_choice(table, "model", path, ERROR_MODELS, defaults.model),
        reflectance_rel=reflectance_rel,
        calibration=_choice(table, "calibration", path, CALIBRATIONS, defaults.calibration),
        calibration_rel=number("calibration_rel", defaults.calibration_rel),
        rotation_coupling=_choice(
            table, "rotation_coupling", path, ROTATION_COUPLINGS, defaults.rotation_coupling
        ),
        images_per_row=_images_per_row(table, path, series),
        angle_deg=angle,
        rotation_deg=number("rotation_deg", angle),
        camera_deg=number("camera_deg", angle),
        propagate_angles=_boolean(table, "propagate_angles", path, "errors.", True),
        angle_method=_choice(table, "angle_method", path, ANGLE_METHODS, defaults.angle_method),
        hierarchical=_boolean(table, "hierarchical", path, "errors.", True),
        sample_sd_prior=number("sample_sd_prior", defaults.sample_sd_prior, positive=True),
        repeatability=repeatability,
        repeatability_sd_prior=number(
            "repeatability_sd_prior", defaults.repeatability_sd_prior, positive=True
        ),
        expected_repeatability=number(
            "expected_repeatability",
            reflectance_rel or defaults.expected_repeatability,
            positive=True,
        ),
    )
