"""Validating a parsed scene document into a :class:`Scene`."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from brdf_infer.errors import BadInputError
from brdf_infer.model.params import (
    DPHI_NAME,
    PAPER_CONSTANTS,
    PARAMETER_SETS,
    HemisphereConstants,
    with_dphi_scale,
)
from brdf_infer.model.priors import DEFAULT_PRIORS, PRIOR_NAMES, parse_prior
from brdf_infer.scene._campaigns import parse_campaigns
from brdf_infer.scene._errors import parse_errors
from brdf_infer.scene._fields import _boolean, _choice, _count, _number, _string, _table
from brdf_infer.scene._records import (
    TARGET_CHOICES,
    ModelSettings,
    OutputSettings,
    PaperFitSettings,
    Scene,
    SeriesGeometry,
)
from brdf_infer.scene._setups import _parse_instrument, _parse_raytrace, check_instrument
from brdf_infer.scene._tables import (
    _model_family,
    _parse_design,
    _parse_references,
    _parse_studies,
    _scene_name,
    _selection,
)
from brdf_infer.tables.bsdf_measurements import BSDF_SERIES, is_bsdf_path
from brdf_infer.tables.measurements import QUANTITIES, header_quantity

# the keys a raw_reflectance series needs (a brdf series has no aperture)
APERTURE_KEYS = ("aperture_diameter_mm", "aperture_distance_mm")

_TOP_KEYS = {
    "instrument",
    "name",
    "description",
    "wavelength_nm",
    "measurements",
    "series",
    "errors",
    "model",
    "paper_fit",
    "outputs",
    "priors",
    "raytrace",
    "compare",
    "studies",
    "bsdf",
    "design",
    "reference",
    "campaigns",
}


def parse_scene(document: dict, path: Path) -> Scene:
    """Validate a parsed scene TOML document (see :mod:`brdf_infer.scene` for the schema)."""
    for key in document:
        if key not in _TOP_KEYS:
            raise BadInputError(
                f"unknown key (allowed: {', '.join(sorted(_TOP_KEYS))})", file=path, field=key
            )
    errors_table = document.get("errors", {})
    if not isinstance(errors_table, dict):
        raise BadInputError("expected a table [errors]", file=path, field="errors")
    campaigns, own_errors = (), {}
    if "campaigns" in document:
        campaigns, series, own_errors = parse_campaigns(document, path, errors_table, _parse_series)
        measurements_path, thinning = campaigns[0].measurements_path, (1, 1)
    else:
        measurements_path = path.parent / _string(document, "measurements", path)
        series, thinning = _parse_series(document, path, measurements_path)
    errors = parse_errors(errors_table, path, tuple(series))
    errors = dataclasses.replace(errors, campaign_errors=own_errors)
    model = _table(
        document, "model", path, {"fold", "out_of_plane", "family", *HemisphereConstants._fields}
    )
    family = _model_family(model, path)
    paper = _table(document, "paper_fit", path, {"alpha", "theta_s0_deg", "selection"})
    outputs = _table(
        document,
        "outputs",
        path,
        {"theta_i_deg", "fold", "tis", "maps", "tis_reference", "reference_params", "target"},
    )
    reference_params = _reference_params(outputs, path)
    model_settings = _model_settings(model, path, family)
    theta_i_out = _band_angles(outputs, path)
    prior_table = _table(document, "priors", path, set(PRIOR_NAMES))
    priors = dict(DEFAULT_PRIORS)
    priors.update({name: parse_prior(name, table, path) for name, table in prior_table.items()})
    if priors[DPHI_NAME].fixed:  # Δφ fixed: its factor is in the constants, no parameter
        scaled = with_dphi_scale(model_settings.constants, math.exp(priors[DPHI_NAME].value))
        model_settings = dataclasses.replace(model_settings, constants=scaled)
    wavelength = document.get("wavelength_nm")
    studies = _parse_studies(document, path)
    scene = Scene(
        name=_scene_name(document, path),
        path=path,
        description=_string(document, "description", path, default=""),
        wavelength_nm=None if wavelength is None else _number(document, "wavelength_nm", path),
        measurements_path=measurements_path,
        series=series,
        errors=errors,
        model=model_settings,
        paper_fit=PaperFitSettings(
            alpha=_number(paper, "alpha", path, default=4.5, positive=True),
            theta_s0_deg=_number(paper, "theta_s0_deg", path, default=-12.0),
            selection=_selection(paper, path),
        ),
        outputs=_output_settings(outputs, path, theta_i_out, reference_params),
        priors=priors,
        raytrace=_parse_raytrace(document, path, series),
        studies=studies,
        bsdf_thinning=thinning,
        instrument=_parse_instrument(document, path, series),
        design=_parse_design(document, path, series),
        references=_parse_references(document, path),
        campaigns=campaigns,
    )
    check_instrument(scene, scene.instrument.model, field="instrument.model")
    return scene


def _parse_series(
    document: dict, path: Path, measurements: Path
) -> tuple[dict[str, SeriesGeometry], tuple[int, int]]:
    """The ``[series.NAME]`` tables (one implied for a .BSDF table) and the ``[bsdf]``
    thinning; ``measurements``: the scene's measurement file."""
    from_bsdf = is_bsdf_path(measurements)
    series_table = document.get(
        "series", {BSDF_SERIES: {"quantity": "brdf"}} if from_bsdf else None
    )
    if not isinstance(series_table, dict) or not series_table:
        raise BadInputError(
            "at least one [series.NAME] table is required", file=path, field="series"
        )
    if from_bsdf and set(series_table) != {BSDF_SERIES}:
        raise BadInputError(
            f"a .BSDF table is one series, '{BSDF_SERIES}' (quantity = \"brdf\")",
            file=path,
            field="series",
        )
    bsdf = _table(document, "bsdf", path, {"keep_every_radial", "keep_every_azimuth"})
    thinning = tuple(_count(bsdf, key, path) for key in ("keep_every_radial", "keep_every_azimuth"))
    series = {}
    for name in series_table:
        table = _table(
            series_table,
            name,
            path,
            {*APERTURE_KEYS, "quantity"},
            "series.",
        )
        prefix = f"series.{name}."
        try:
            quantity = _choice(table, "quantity", path, QUANTITIES, "raw_reflectance", "")
            aperture = quantity == "raw_reflectance" or "aperture_diameter_mm" in table
            series[name] = SeriesGeometry(
                _number(table, "aperture_diameter_mm", path, positive=True) if aperture else None,
                _number(table, "aperture_distance_mm", path, positive=True) if aperture else None,
                quantity,
            )
        except BadInputError as error:
            if "quantity" not in table and error.field in APERTURE_KEYS:
                _missing_quantity(name, table, path, measurements, from_bsdf)
            raise BadInputError(error.problem, file=path, field=prefix + str(error.field)) from None
    return series, thinning


def _missing_quantity(
    name: str, table: dict, path: Path, measurements: Path, from_bsdf: bool
) -> None:
    """A series without ``quantity`` (so raw reflectance) that lacks its aperture: where the
    measurement file holds BRDF values, the series most likely forgot ``quantity = "brdf"``.

    Raises:
        BadInputError: naming ``series.NAME.quantity``, when the file holds BRDF values.
    """
    if any(key in table for key in APERTURE_KEYS):
        return  # an aperture half given: the missing key is the problem
    if not from_bsdf and header_quantity(measurements) != "brdf":
        return
    raise BadInputError(
        f'missing: {measurements.name} holds brdf values; set quantity = "brdf" in '
        f"[series.{name}] (for raw reflectance, give {' and '.join(APERTURE_KEYS)} and name "
        "the columns reflectance,reflectance_err)",
        file=path,
        field=f"series.{name}.quantity",
    )


def _reference_params(outputs: dict, path: Path) -> str | None:
    """``[outputs] reference_params``: a name of :data:`brdf_infer.model.params.PARAMETER_SETS`."""
    reference_params = outputs.get("reference_params")
    if reference_params is not None and (
        not isinstance(reference_params, str) or reference_params not in PARAMETER_SETS
    ):
        raise BadInputError(
            f"unknown parameter set {reference_params!r} (known: {', '.join(PARAMETER_SETS)})",
            file=path,
            field="outputs.reference_params",
        )
    return reference_params


def _model_settings(model: dict, path: Path, family: str) -> ModelSettings:
    """The ``[model]`` switches and constants."""
    fold = _boolean(model, "fold", path, "model.", False)
    out_of_plane = _boolean(model, "out_of_plane", path, "model.", True)
    constants = HemisphereConstants(
        *(
            _number(model, name, path, default=getattr(PAPER_CONSTANTS, name))
            for name in HemisphereConstants._fields
        )
    )
    return ModelSettings(fold=fold, out_of_plane=out_of_plane, constants=constants, family=family)


def _band_angles(outputs: dict, path: Path) -> list:
    """``[outputs] theta_i_deg``: angles in [0, 90) deg (empty: the measured ones)."""
    theta_i_out = outputs.get("theta_i_deg", [])
    if not isinstance(theta_i_out, list) or not all(
        isinstance(v, int | float) and not isinstance(v, bool) and 0 <= v < 90 for v in theta_i_out
    ):
        raise BadInputError(
            "expected a list of angles in [0, 90) deg", file=path, field="outputs.theta_i_deg"
        )
    return theta_i_out


def _output_settings(
    outputs: dict, path: Path, theta_i_out: list, reference_params: str | None
) -> OutputSettings:
    """The ``[outputs]`` table, its band angles and reference set already checked."""
    return OutputSettings(
        theta_i_deg=tuple(float(v) for v in theta_i_out) if theta_i_out else None,
        fold=_boolean(outputs, "fold", path, "outputs.", False),
        tis=_boolean(outputs, "tis", path, "outputs.", True),
        maps=_boolean(outputs, "maps", path, "outputs.", True),
        tis_reference=(
            None
            if "tis_reference" not in outputs
            else path.parent / _string(outputs, "tis_reference", path)
        ),
        reference_params=reference_params,
        target=_choice(outputs, "target", path, TARGET_CHOICES, "auto", prefix="outputs."),
    )
