"""A pooled scene's ``[campaigns.NAME]`` tables: several measurement files of one coating at
one wavelength (labs, sessions, instruments), each with its own series, apertures and data
options of the error model, sharing the coating's parameters and τ.

Schema (in place of the top-level ``measurements`` and ``[series.NAME]``)::

    [campaigns.NAME]                         # NAME: letters, digits, "-", "_" (no "/")
    measurements = "labA.csv"                # required, relative to the scene file
    [campaigns.NAME.series.SERIES]           # the series of that file, as [series.NAME]
    aperture_diameter_mm = 7.2
    aperture_distance_mm = 103.8
    [campaigns.NAME.errors]                  # [the scene's [errors]] this campaign's own
    calibration_rel = 0.02                   #   data options (DATA_OPTIONS): calibration,
                                             #   calibration_rel, reflectance_rel,
                                             #   images_per_row, rotation_coupling,
                                             #   angle_deg, rotation_deg, camera_deg
    [campaigns.NAME.bsdf]                    # [1, 1] thinning of a .BSDF file

The pooled table names each campaign's series and samples ``NAME/SERIES``, ``NAME/SAMPLE``
(:func:`brdf_infer.tables.measurements.pooled_measurements`); the scene's other tables
(``[design] series``, ``[instrument.series.…]``, a per-series ``images_per_row`` in
``[errors]``) use those names.
"""

from __future__ import annotations

import re
from pathlib import Path

from brdf_infer.errors import BadInputError
from brdf_infer.model.error_model import DATA_OPTIONS
from brdf_infer.scene._errors import parse_errors
from brdf_infer.scene._fields import _string, _table
from brdf_infer.scene._records import Campaign, SeriesGeometry
from brdf_infer.tables.measurements import CAMPAIGN_SEPARATOR

CAMPAIGN_KEYS = {"measurements", "series", "errors", "bsdf"}
_NAME = re.compile(r"[A-Za-z0-9_-]+")


def parse_campaigns(
    document: dict, path: Path, errors_table: dict, parse_series
) -> tuple[tuple[Campaign, ...], dict[str, SeriesGeometry], dict[str, dict]]:
    """The campaigns of a pooled scene, the pooled series (prefixed names) and each
    campaign's own data options (:attr:`ErrorSettings.campaign_errors`). ``parse_series``:
    the scene's reader of a ``series`` and ``bsdf`` table (document, path, measurements).

    Raises:
        BadInputError: a malformed campaign, naming ``campaigns.NAME.…``.
    """
    tables = document["campaigns"]
    if not isinstance(tables, dict) or not tables:
        raise BadInputError(
            "expected one or more [campaigns.NAME] tables", file=path, field="campaigns"
        )
    for key in ("measurements", "series", "bsdf"):
        if key in document:
            raise BadInputError(
                "a scene with [campaigns] names its files and series under [campaigns.NAME] only",
                file=path,
                field=key,
            )
    campaigns, series, overrides = [], {}, {}
    for name, table in tables.items():
        try:
            campaign, own = _campaign(name, table, path, errors_table, parse_series)
        except BadInputError as error:
            field = f"campaigns.{name}" + (f".{error.field}" if error.field else "")
            raise BadInputError(error.problem, file=error.file or path, field=field) from None
        campaigns.append(campaign)
        overrides[name] = own
        for series_name, geometry in campaign.series.items():
            series[f"{name}{CAMPAIGN_SEPARATOR}{series_name}"] = geometry
    return tuple(campaigns), series, overrides


def _campaign(
    name: str, table, path: Path, errors_table: dict, parse_series
) -> tuple[Campaign, dict]:
    """One ``[campaigns.NAME]`` table (fields named relative to it) and its own data options."""
    if not _NAME.fullmatch(name):
        raise BadInputError("a campaign's name is letters, digits, '-' and '_'", file=path)
    if not isinstance(table, dict):
        raise BadInputError("expected a table", file=path)
    for key in table:
        if key not in CAMPAIGN_KEYS:
            raise BadInputError(
                f"unknown key (allowed: {', '.join(sorted(CAMPAIGN_KEYS))})", file=path, field=key
            )
    measurements = path.parent / _string(table, "measurements", path)
    series, thinning = parse_series(table, path, measurements)
    own_table = _table(table, "errors", path, set(DATA_OPTIONS))
    # the scene's data options beneath the campaign's (a per-series images_per_row of the
    # scene names pooled series, not this file's)
    shared = {
        key: value
        for key, value in errors_table.items()
        if key in DATA_OPTIONS and not (key == "images_per_row" and isinstance(value, dict))
    }
    resolved = parse_errors({**shared, **own_table}, path, tuple(series))
    keys = set(own_table)
    if "angle_deg" in keys:  # the default of the two angle scales
        keys |= {"rotation_deg", "camera_deg"}
    own = {key: getattr(resolved, key) for key in sorted(keys)}
    return Campaign(name, measurements, series, thinning), own
