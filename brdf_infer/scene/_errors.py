"""The ``[errors]`` table of a scene (:class:`brdf_infer.model.error_model.ErrorSettings`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from brdf_infer.errors import BadInputError
from brdf_infer.model.error_model import (
    ANGLE_METHODS,
    CALIBRATIONS,
    DERIVED,
    ERROR_MODELS,
    LEARNED,
    ROTATION_COUPLINGS,
    ErrorSettings,
)
from brdf_infer.runs.folder import RunFolder
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


# a run's τ draws as a prior: at least this many draws, summarised by this many quantiles of
# ln τ, the centres of a Gaussian kernel density (Silverman's bandwidth from all the draws,
# wider where the quantiles lie further apart)
MIN_TAU_DRAWS = 100
TAU_KERNELS = 100


def _sample_spread(table: dict, path: Path, number) -> dict:
    """τ's keys of ``[errors]``: ``sample_sd`` (``"learned"`` or a stated value, which needs
    ``sample_sd_source``) or ``sample_sd_from`` (a run whose τ posterior is the prior: a
    Gaussian kernel density of its draws' ln τ, ``sample_sd_log_kde``)."""
    value = table.get("sample_sd", LEARNED)
    if isinstance(value, str) and value != LEARNED:
        raise BadInputError(
            f'expected "{LEARNED}" or a number >= 0, got {value!r}',
            file=path,
            field="errors.sample_sd",
        )
    source = table.get("sample_sd_source", "")
    if not isinstance(source, str):
        raise BadInputError("expected words", file=path, field="errors.sample_sd_source")
    run = table.get("sample_sd_from", "")
    if not isinstance(run, str):
        raise BadInputError("expected a run folder", file=path, field="errors.sample_sd_from")
    if value != LEARNED:
        if run:
            raise BadInputError(
                "a stated τ (errors.sample_sd) and a run's τ (errors.sample_sd_from) exclude "
                "each other",
                file=path,
                field="errors.sample_sd_from",
            )
        if not source.strip():
            raise BadInputError(
                "a stated τ needs its source in words (errors.sample_sd_source)",
                file=path,
                field="errors.sample_sd_source",
            )
        return {"sample_sd": number("sample_sd", 0.0), "sample_sd_source": source}
    if not run:
        return {"sample_sd_source": source}
    try:
        draws = RunFolder(path.parent / run).posterior_draws("sample_sd")
    except BadInputError as error:
        raise BadInputError(error.problem, file=error.file, field="errors.sample_sd_from") from None
    draws = draws[np.isfinite(draws) & (draws > 0)]
    if draws.size < MIN_TAU_DRAWS:
        raise BadInputError(
            f"the run has {draws.size} positive draws of τ (at least {MIN_TAU_DRAWS} needed)",
            file=path.parent / run,
            field="errors.sample_sd_from",
        )
    logs = np.log(draws)
    centres = np.quantile(logs, (np.arange(TAU_KERNELS) + 0.5) / TAU_KERNELS)
    spread = min(np.std(logs), (np.quantile(logs, 0.75) - np.quantile(logs, 0.25)) / 1.34)
    bandwidth = 0.9 * spread * logs.size ** (-0.2)  # Silverman's rule
    # where the quantiles lie further apart than that (the tails), each kernel as wide as its
    # neighbours' distance: a smooth density without bumps for a sampler to stick in
    gaps = np.diff(centres)
    local = np.maximum(np.append(gaps[:1], gaps), np.append(gaps, gaps[-1:]))
    widths = np.maximum(bandwidth, local)
    return {
        "sample_sd_source": source,
        "sample_sd_from": run,
        "sample_sd_log_kde": (tuple(map(float, centres)), tuple(map(float, widths))),
    }


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
    keys = set(ErrorSettings.__dataclass_fields__) - set(DERIVED)
    table = _table({"errors": table}, "errors", path, keys)

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
    tau = _sample_spread(table, path, number)
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
        **tau,
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
