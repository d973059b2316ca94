"""Measurement rows from a tabular .BSDF file (Zemax format): a vendor's or an imaging
sphere's BRDF table, read as BRDF rows of one series ``bsdf`` and one sample ``bsdf``.

Each table value at (AOI, azimuth, radial) of the file's specular frame becomes a row at the
model's (θi, θ, φ) (:func:`brdf_infer.bsdf_file.specular_frame_to_model`); directions below the
horizon and zero values are left out. Rows in the plane of incidence (φ = 180° or 0° to 1e-9°)
get a signed θs like CSV rows; the others keep their azimuth. A direction the table lists more
than once (radial 0, the specular ray, in every azimuth row; a negative radial that mirrors
another azimuth) is one row, the first listed: a CSV must not repeat a row either.
``keep_every_radial`` /
``keep_every_azimuth`` thin the table (every k-th radial and azimuth sample, counted from the
first), since a full table holds 10⁴–10⁵ values.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from brdf_infer.bsdf_file import read_bsdf, specular_frame_to_model
from brdf_infer.errors import BadInputError
from brdf_infer.measurements import Measurements

BSDF_SERIES = "bsdf"
IN_PLANE_TOLERANCE_DEG = 1e-9


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
    azimuth = table.azimuth_deg[::keep_every_azimuth]
    radial = table.radial_deg[::keep_every_radial]
    values = table.bsdf[0][:, ::keep_every_azimuth, ::keep_every_radial]
    theta_i, theta_s, phi_s, brdf = [], [], [], []
    grid_azimuth, grid_radial = np.meshgrid(azimuth, radial, indexing="ij")
    for aoi, block in zip(table.theta_i_deg, values, strict=True):
        theta, phi, z = (
            np.asarray(a) for a in specular_frame_to_model(aoi, grid_azimuth, grid_radial)
        )
        keep = (z > 0.0) & (block > 0.0) & (theta < 90.0)
        theta, phi, value = theta[keep], phi[keep], block[keep]
        forward = np.abs(phi - 180.0) < IN_PLANE_TOLERANCE_DEG
        backward = (phi < IN_PLANE_TOLERANCE_DEG) | (phi > 360.0 - IN_PLANE_TOLERANCE_DEG)
        theta_i.append(np.full(value.size, float(aoi)))
        theta_s.append(np.where(backward, -theta, theta))
        phi_s.append(np.where(forward | backward, np.nan, phi))
        brdf.append(value)
    columns = [np.concatenate(c) for c in (theta_i, theta_s, phi_s, brdf)]
    if columns[3].size == 0:
        raise BadInputError("no positive BRDF value above the horizon", file=path)
    first = _first_of_each_direction(*columns[:3])
    theta_i_deg, theta_s_deg, phi_s_deg, brdf_values = (c[first] for c in columns)
    count = brdf_values.size
    return Measurements(
        path=path,
        series=np.full(count, BSDF_SERIES),
        sample=np.full(count, BSDF_SERIES),
        theta_i_deg=theta_i_deg,
        theta_s_deg=theta_s_deg,
        reflectance=brdf_values,
        reflectance_err=None,
        quantity="brdf",
        phi_s_deg=phi_s_deg,
    )


def _first_of_each_direction(
    theta_i: np.ndarray, theta_s: np.ndarray, phi_s: np.ndarray
) -> np.ndarray:
    """Indices of the first row of each (θi, θs, φs) direction (to 1e-9°), in table order."""
    digits = 9
    keys = np.stack(
        [
            theta_i,
            np.round(theta_s, digits),
            np.where(np.isnan(phi_s), -1.0, np.round(phi_s, digits)),
        ],
        axis=1,
    )
    _, first = np.unique(keys, axis=0, return_index=True)
    return np.sort(first)
