"""The settings a new row may take: a grid over the scene's ``[design]`` range, or a CSV.

A candidate is one new measurement row: its series (whose aperture and calibration it shares),
its sample (the series' sample with the most rows: a new row is taken on a sample already in
the lab) and its geometry (θi, signed in-plane θs, or polar θs with an azimuth φs out of the
plane). The instrument reaches a setting when θi and θs lie in the ``[design]`` ranges and the
camera stays clear of the incident beam: in the plane the camera sits at the lab angle θi + θs
from the direction back to the source, so |θi + θs| ≥ ``source_clearance_deg``.

Candidate CSV (header required): ``theta_i_deg,theta_s_deg`` and optionally ``series`` (default
the design series) and ``phi_s_deg`` (out of the plane; empty or absent: in the plane).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from brdf_infer.errors import BadInputError
from brdf_infer.measurements import Measurements
from brdf_infer.scene import DesignSettings, Scene


@dataclass(frozen=True)
class Candidates:
    """Candidate settings, one per entry.

    Attributes:
        series: series of each candidate.
        theta_i_deg: θi [deg].
        theta_s_deg: θs [deg]: signed in the plane, polar out of it.
        phi_s_deg: azimuth [deg], NaN in the plane.
    """

    series: np.ndarray
    theta_i_deg: np.ndarray
    theta_s_deg: np.ndarray
    phi_s_deg: np.ndarray

    def __len__(self) -> int:
        return len(self.series)

    def as_measurements(self, measurements: Measurements) -> Measurements:
        """The candidates as measurement rows (value 1: only their geometry is used), each on
        its series' sample with the most rows in ``measurements``."""
        samples = np.array([design_sample(measurements, name) for name in self.series])
        out_of_plane = np.isfinite(self.phi_s_deg)
        return Measurements(
            path=measurements.path,
            series=self.series,
            sample=samples,
            theta_i_deg=self.theta_i_deg,
            theta_s_deg=self.theta_s_deg,
            reflectance=np.full(len(self), 0.5),
            reflectance_err=None,
            quantity=measurements.quantity,
            phi_s_deg=self.phi_s_deg if np.any(out_of_plane) else None,
        )

    def row(self, index: int) -> dict:
        """One candidate's settings as JSON values (φs: 180 forward, 0 backward in the plane)."""
        phi = float(self.phi_s_deg[index])
        theta_s = float(self.theta_s_deg[index])
        return {
            "theta_i_deg": float(self.theta_i_deg[index]),
            "theta_s_deg": theta_s,
            "phi_s_deg": phi if math.isfinite(phi) else (180.0 if theta_s >= 0 else 0.0),
            "series": str(self.series[index]),
        }


def design_series(scene: Scene, measurements: Measurements, series: str | None = None) -> str:
    """The series new rows join: ``series``, else ``[design] series``, else the one with the
    most rows.

    Raises:
        BadInputError: a series the scene lacks.
    """
    name = series or scene.design.series
    if name is None:
        names, counts = np.unique(measurements.series, return_counts=True)
        return str(names[int(np.argmax(counts))])
    if name not in scene.series or name not in set(measurements.series):
        raise BadInputError(
            f"no measured series {name!r} in scene '{scene.name}' "
            f"(known: {', '.join(dict.fromkeys(measurements.series))})",
            field="series",
        )
    return name


def design_sample(measurements: Measurements, series: str) -> str:
    """The sample of ``series`` with the most rows (the one a new row is taken on)."""
    samples, counts = np.unique(
        measurements.sample[measurements.series == series], return_counts=True
    )
    return str(samples[int(np.argmax(counts))])


def reachable(settings: DesignSettings, theta_i, theta_s, phi_s) -> np.ndarray:
    """True where the instrument reaches the setting (module docstring)."""
    theta_i, theta_s = np.asarray(theta_i, float), np.asarray(theta_s, float)
    in_plane = ~np.isfinite(np.asarray(phi_s, float))
    low_i, high_i = settings.theta_i_deg
    low_s, high_s = settings.theta_s_deg
    inside = (theta_i >= low_i - 1e-9) & (theta_i <= high_i + 1e-9)
    inside &= np.where(
        in_plane, (theta_s >= low_s - 1e-9) & (theta_s <= high_s + 1e-9), theta_s <= high_s
    )
    clear = np.abs(theta_i + theta_s) >= settings.source_clearance_deg - 1e-9
    return inside & (clear | ~in_plane)


def grid_candidates(settings: DesignSettings, series: str) -> Candidates:
    """Every reachable in-plane setting on the ``[design]`` grid, in the given series."""
    step = settings.step_deg
    theta_i = np.arange(settings.theta_i_deg[0], settings.theta_i_deg[1] + 1e-9, step)
    theta_s = np.arange(settings.theta_s_deg[0], settings.theta_s_deg[1] + 1e-9, step)
    grid_i, grid_s = (a.reshape(-1) for a in np.meshgrid(theta_i, theta_s, indexing="ij"))
    phi = np.full(grid_i.shape, np.nan)
    keep = reachable(settings, grid_i, grid_s, phi)
    count = int(np.sum(keep))
    return Candidates(np.full(count, series), grid_i[keep], grid_s[keep], phi[keep])


def _number(text: str, field: str, where: dict) -> float:
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise BadInputError(f"expected a number, got {text!r}", field=field, **where) from None
    if not math.isfinite(value):
        raise BadInputError(f"expected a finite number, got {text!r}", field=field, **where)
    return value


def read_candidates(
    path: str | Path, scene: Scene, measurements: Measurements, series: str
) -> Candidates:
    """Candidate settings from a CSV (module docstring), each checked against the instrument.

    Raises:
        BadInputError: an unreadable file, a missing column, a non-numeric angle, a series the
            scene has not measured, or a setting the instrument cannot reach (naming file,
            row and field).
    """
    path = Path(path)
    try:
        with path.open(newline="") as handle:
            rows = list(csv.DictReader(handle))
            header = rows[0].keys() if rows else []
    except (OSError, UnicodeDecodeError) as error:
        raise BadInputError(f"cannot read: {error}", file=path) from None
    for column in ("theta_i_deg", "theta_s_deg"):
        if column not in header:
            raise BadInputError("missing column", file=path, field=column)
    known = set(measurements.series)
    names, theta_i, theta_s, phi = [], [], [], []
    for number, row in enumerate(rows, start=1):
        where = {"file": path, "row": number}
        name = (row.get("series") or "").strip() or series
        if name not in known:
            raise BadInputError(
                f"no measured series {name!r} in scene '{scene.name}'", field="series", **where
            )
        azimuth = (row.get("phi_s_deg") or "").strip()
        values = [_number(row[c], c, where) for c in ("theta_i_deg", "theta_s_deg")]
        values.append(_number(azimuth, "phi_s_deg", where) if azimuth else math.nan)
        if not reachable(scene.design, *values):
            field = (
                "theta_i_deg"
                if not scene.design.theta_i_deg[0] <= values[0] <= scene.design.theta_i_deg[1]
                else "theta_s_deg"
            )
            raise BadInputError(
                f"the instrument cannot reach θi = {values[0]:g}°, θs = {values[1]:g}° "
                f"([design] θi {list(scene.design.theta_i_deg)}, θs "
                f"{list(scene.design.theta_s_deg)}, camera ≥ "
                f"{scene.design.source_clearance_deg:g}° from the beam)",
                field=field,
                **where,
            )
        names.append(name)
        theta_i.append(values[0])
        theta_s.append(values[1])
        phi.append(values[2])
    if not names:
        raise BadInputError("no candidate rows", file=path)
    return Candidates(np.array(names), np.array(theta_i), np.array(theta_s), np.array(phi))
