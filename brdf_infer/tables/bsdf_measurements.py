"""Measurement rows from a tabular .BSDF file (Zemax format): a vendor's or an imaging
sphere's BRDF table, read as BRDF rows of one series ``bsdf`` and one sample ``bsdf``.

Each table value at (AOI, azimuth, radial) of the file's specular frame becomes a row at the
model's (θi, θ, φ) (:func:`brdf_infer.tables.bsdf_file.specular_frame_to_model`). Rows in the plane
of incidence (φ = 180° or 0° to 1e-9°) get a signed θs like CSV rows; the others keep their
azimuth. A direction the table lists more than once (radial 0, the specular ray, in every
azimuth row; a negative radial that mirrors another azimuth) is one row, the first listed: a
CSV must not repeat a row either. ``keep_every_radial`` / ``keep_every_azimuth`` thin the
table (every k-th radial and azimuth sample, counted from the first), since a full table
holds 10⁴–10⁵ values.

Left out, each counted by the rule :mod:`brdf_infer.tables.screening` states (the run's
verdict names the counts): directions below the horizon, zero cells (below the detection
limit) and dropouts (a value far below every neighbour). The record rides on the rows as
:attr:`Measurements.screening`.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from brdf_infer.errors import BadInputError
from brdf_infer.tables.bsdf_file import BsdfFile, read_bsdf, specular_frame_to_model
from brdf_infer.tables.measurements import Measurements
from brdf_infer.tables.screening import TableScreening, dropout_mask, neighbour_median

BSDF_SERIES = "bsdf"
IN_PLANE_TOLERANCE_DEG = 1e-9
HORIZON_TOLERANCE = 1e-9  # |cos θ| of a cell on the horizon (θ = 90°: left out, not counted)


def is_bsdf_path(path: Path) -> bool:
    """A measurements path that names a .BSDF table (case-insensitive suffix)."""
    return path.suffix.lower() == ".bsdf"


def measurements_from_bsdf(
    path: str | Path, keep_every_radial: int = 1, keep_every_azimuth: int = 1
) -> Measurements:
    """BRDF rows of a tabular .BSDF file (module docstring).

    Raises:
        BadInputError: the file is malformed (the reader's message: file and line), holds a
            BTDF, or no positive value above the horizon.
    """
    path = Path(path)
    table = read_bsdf(path)
    if table.scatter_type != "BRDF":
        raise BadInputError(f"holds a {table.scatter_type}, not a BRDF", file=path)
    aoi = table.theta_i_deg
    if np.any((aoi < 0.0) | (aoi >= 90.0)) or np.unique(aoi).size < aoi.size:
        raise BadInputError(
            f"angles of incidence must be distinct and lie in [0, 90) deg, got {aoi.tolist()}",
            file=path,
            field="AngleOfIncidence",
        )
    cells = _cells(table, keep_every_radial, keep_every_azimuth)
    usable = cells.above & (cells.value > 0.0) & ~cells.dropout
    if not usable.any():
        raise BadInputError("no positive BRDF value above the horizon", file=path)
    first = np.flatnonzero(usable)[_first_of_each_direction(*(c[usable] for c in cells[:3]))]
    count = first.size
    return Measurements(
        path=path,
        series=np.full(count, BSDF_SERIES),
        sample=np.full(count, BSDF_SERIES),
        theta_i_deg=cells.theta_i[first],
        theta_s_deg=cells.theta_s[first],
        reflectance=cells.value[first],
        reflectance_err=None,
        quantity="brdf",
        phi_s_deg=cells.phi_s[first],
        screening=_screening(cells, usable),
    )


class _Cells(NamedTuple):
    """Every cell of the thinned table, flattened in table order."""

    theta_i: np.ndarray  # θi [deg]
    theta_s: np.ndarray  # θs [deg], signed in the plane of incidence
    phi_s: np.ndarray  # φs [deg], NaN in the plane
    value: np.ndarray  # [sr⁻¹]
    above: np.ndarray  # above the horizon (θ < 90°)
    below: np.ndarray  # below it (not on it, to HORIZON_TOLERANCE)
    dropout: np.ndarray  # brdf_infer.tables.screening.dropout_mask
    around: np.ndarray  # the median of its neighbours [sr⁻¹]


def _cells(table: BsdfFile, keep_every_radial: int, keep_every_azimuth: int) -> _Cells:
    """Every cell of the thinned table (:class:`_Cells`)."""
    azimuth = table.azimuth_deg[::keep_every_azimuth]
    radial = table.radial_deg[::keep_every_radial]
    values = table.bsdf[0][:, ::keep_every_azimuth, ::keep_every_radial]
    grid_azimuth, grid_radial = np.meshgrid(azimuth, radial, indexing="ij")
    columns: list[list[np.ndarray]] = [[] for _ in range(8)]
    for aoi, block in zip(table.theta_i_deg, values, strict=True):
        theta, phi, z = (
            np.asarray(a) for a in specular_frame_to_model(aoi, grid_azimuth, grid_radial)
        )
        above = (z > 0.0) & (theta < 90.0)
        forward = np.abs(phi - 180.0) < IN_PLANE_TOLERANCE_DEG
        backward = (phi < IN_PLANE_TOLERANCE_DEG) | (phi > 360.0 - IN_PLANE_TOLERANCE_DEG)
        for column, cell in zip(
            columns,
            (
                np.full(block.shape, float(aoi)),
                np.where(backward, -theta, theta),
                np.where(forward | backward, np.nan, phi),
                block,
                above,
                z < -HORIZON_TOLERANCE,
                dropout_mask(block, above),
                neighbour_median(block, above),
            ),
            strict=True,
        ):
            column.append(np.ravel(cell))
    return _Cells(*(np.concatenate(column) for column in columns))


def _directions(cells: _Cells, mask: np.ndarray) -> set[tuple[float, float, float]]:
    """The distinct directions of the cells in ``mask`` (:func:`_key`)."""
    chosen = (cells.theta_i[mask], cells.theta_s[mask], cells.phi_s[mask])
    return {_key(*row) for row in zip(*chosen, strict=True)}


def _screening(cells: _Cells, usable: np.ndarray) -> TableScreening:
    """What the rows leave out (:mod:`brdf_infer.tables.screening`), each direction once."""
    theta_i, theta_s, phi_s, value, above, below, dropout, around = cells
    kept = _directions(cells, usable)
    zero_rows = _directions(cells, above & (value == 0.0)) - kept
    dropped = np.flatnonzero(dropout)
    dropped = dropped[_first_of_each_direction(theta_i[dropped], theta_s[dropped], phi_s[dropped])]
    dropouts = tuple(
        {
            "theta_i_deg": float(theta_i[i]),
            "theta_s_deg": float(theta_s[i]),
            **({} if np.isnan(phi_s[i]) else {"phi_s_deg": float(phi_s[i])}),
            "value": float(value[i]),
            "neighbours": float(around[i]),
        }
        for i in dropped
        if _key(theta_i[i], theta_s[i], phi_s[i]) not in kept
    )
    directions = np.array(sorted(zero_rows), float).reshape(-1, 3)
    return TableScreening(
        zero_cells=len(zero_rows),
        detection_limit=float(np.min(value[above & (value > 0.0)])),
        below_horizon=int(np.sum(below & (value > 0.0))),
        dropouts=dropouts,
        zero_directions=np.column_stack(
            [directions[:, 0], np.abs(directions[:, 1]), _azimuth(directions)]
        ),
    )


_DIGITS = 9


def _key(theta_i: float, theta_s: float, phi_s: float) -> tuple[float, float, float]:
    """A direction (θi, θs, φs) [deg] to 1e-9° (φs −1 in the plane)."""
    return (
        float(theta_i),
        round(float(theta_s), _DIGITS),
        -1.0 if np.isnan(phi_s) else round(float(phi_s), _DIGITS),
    )


def _azimuth(directions: np.ndarray) -> np.ndarray:
    """φ [deg] of (θi, θs, φs or −1 in the plane) directions: 180° forward, 0° backward."""
    in_plane = directions[:, 2] < 0.0
    return np.where(in_plane, np.where(directions[:, 1] < 0.0, 0.0, 180.0), directions[:, 2])


def _first_of_each_direction(
    theta_i: np.ndarray, theta_s: np.ndarray, phi_s: np.ndarray
) -> np.ndarray:
    """Indices of the first row of each (θi, θs, φs) direction (to 1e-9°), in table order."""
    keys = np.stack(
        [
            theta_i,
            np.round(theta_s, _DIGITS),
            np.where(np.isnan(phi_s), -1.0, np.round(phi_s, _DIGITS)),
        ],
        axis=1,
    )
    _, first = np.unique(keys, axis=0, return_index=True)
    return np.sort(first)
