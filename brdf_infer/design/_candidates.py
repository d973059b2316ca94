"""The settings a new row may take: the reachable points of a grid, or a CSV.

A candidate is one new measurement row: its series (whose aperture it has), its session (a new
one with its own reference measurement, Eq. 2, or the measured session of its series it
continues, sharing that reference and the rotation settings), its sample (the series' sample
with the most rows, or the scene's for a new series: a new row is taken on a sample already in
the lab) and its geometry (θi, signed in-plane θs, or polar θs with an azimuth φs out of the
plane).

The instrument reaches a setting when θi and θs lie in the ``[design]`` ranges and the camera
stays clear of the incident beam: in the plane the camera sits at the lab angle θi + θs from the
direction back to the source, so |θi + θs| ≥ ``source_clearance_deg``. The grid is every
in-plane setting whose θi and θs are multiples of ``step_deg`` (θi 0–89°, θs ±89°), the limits
of the reachable ranges added; the settings the instrument cannot reach are left out and
counted by the first limit they break (θi, θs, then the beam).

Candidate CSV (header required): ``theta_i_deg,theta_s_deg`` and optionally ``series`` (default
the design series) and ``phi_s_deg`` (out of the plane; empty or absent: in the plane).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from brdf_infer.errors import BadInputError
from brdf_infer.scene import DesignSettings, Scene, SeriesGeometry
from brdf_infer.tables.measurements import Measurements

NEW_SAMPLE = "new sample"  # the name of a physical sample not yet measured (design --new-sample)


@dataclass(frozen=True)
class Candidates:
    """Candidate settings, one per entry.

    Attributes:
        series: series of each candidate.
        theta_i_deg: θi [deg].
        theta_s_deg: θs [deg]: signed in the plane, polar out of it.
        phi_s_deg: azimuth [deg], NaN in the plane.
        session: ``"new"`` (a new reference measurement) or the series whose measured
            session the row continues; None: not yet said (:func:`~brdf_infer.design.design`
            gives each row a new session unless it continues the ``same_session`` series;
            :func:`~brdf_infer.design.predictive` takes every row as continuing its series).
        left_out: for a grid, ``{"grid", "reachable", "theta_i_deg", "theta_s_deg",
            "source_clearance_deg"}``: the grid's settings, those kept, and those left out
            by each limit (and ``"measured"``: reachable ones a continued session holds,
            :meth:`without_measured`); None for a CSV.
    """

    series: np.ndarray
    theta_i_deg: np.ndarray
    theta_s_deg: np.ndarray
    phi_s_deg: np.ndarray
    session: np.ndarray | None = None
    left_out: dict[str, int] | None = None

    def __len__(self) -> int:
        return len(self.series)

    def sessions(self) -> np.ndarray:
        """The session of every row (None taken as continuing its series')."""
        return self.series.astype(str) if self.session is None else self.session

    def subset(self, index) -> Candidates:
        """The candidates at positions ``index`` (their sessions kept; no grid counts)."""
        index = np.asarray(index, int)
        session = None if self.session is None else self.session[index]
        return Candidates(
            self.series[index],
            self.theta_i_deg[index],
            self.theta_s_deg[index],
            self.phi_s_deg[index],
            session,
        )

    def without_measured(self, measurements: Measurements) -> Candidates:
        """The candidates less those that would repeat a measured row of the session they
        continue (same series, sample and angles: a table holds one row per setting, and the
        measurement loader refuses a second)."""
        taken = set(
            zip(
                measurements.series.astype(str),
                measurements.sample.astype(str),
                np.round(measurements.theta_i_deg, 9),
                np.round(measurements.theta_s_deg, 9),
                strict=True,
            )
        )
        rows = self.as_measurements(measurements)
        keep = np.array(
            [
                session == "new"
                or (str(s), str(m), round(float(i), 9), round(float(t), 9)) not in taken
                for session, s, m, i, t in zip(
                    self.sessions(),
                    rows.series,
                    rows.sample,
                    rows.theta_i_deg,
                    rows.theta_s_deg,
                    strict=True,
                )
            ],
            bool,
        )
        if keep.all():
            return self
        left_out = None
        if self.left_out is not None:
            left_out = {**self.left_out, "measured": int(np.sum(~keep))}
        return replace(self.subset(np.flatnonzero(keep)), left_out=left_out)

    def in_sessions(self, same_session: str | None) -> Candidates:
        """The candidates, each row in a new session unless its series is ``same_session``
        (rows whose session is already said keep it)."""
        if self.session is not None:
            return self
        session = np.where(self.series == same_session, self.series, "new").astype(str)
        return replace(self, session=session)

    def as_measurements(self, measurements: Measurements, new_sample: bool = False) -> Measurements:
        """The candidates as measurement rows (value 1: only their geometry is used), each on
        its series' sample with the most rows in ``measurements`` (``new_sample``: every one on
        one sample not yet measured, :data:`NEW_SAMPLE`)."""
        samples = np.array(
            [NEW_SAMPLE if new_sample else design_sample(measurements, n) for n in self.series]
        )
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
            "session": str(self.sessions()[index]),
        }


def design_series(
    scene: Scene,
    measurements: Measurements,
    series: str | None = None,
    same_session: str | None = None,
    aperture: tuple[float, float] | None = None,
) -> str:
    """The series new rows join: ``series``, else ``same_session``, else ``[design] series``,
    else the one with the most rows. A series without rows is a new one: its aperture from
    the scene's ``[series.NAME]`` or ``aperture`` (:func:`session_scene`).

    Raises:
        BadInputError: ``same_session`` not a measured series; a new series without an
            aperture; an aperture for a measured series.
    """
    measured = list(dict.fromkeys(measurements.series))
    if same_session is not None and same_session not in measured:
        raise BadInputError(
            f"no measured series {same_session!r} in scene '{scene.name}' to continue "
            f"(known: {', '.join(measured)})",
            field="same_session",
        )
    name = series or same_session or scene.design.series
    if name is None:
        names, counts = np.unique(measurements.series, return_counts=True)
        name = str(names[int(np.argmax(counts))])
    if aperture is not None and name in measured:
        raise BadInputError(
            f"series {name!r} has measured rows and their aperture; an aperture is for a new "
            "series (name one with --series)",
            field="aperture",
        )
    if name not in measured and name not in scene.series and aperture is None:
        raise BadInputError(
            f"no measured series {name!r} in scene '{scene.name}' (known: "
            f"{', '.join(measured)}), and no aperture for a new one (a [series.{name}] table "
            "in the scene — the copy the run recorded, unless --scene names the file as it is "
            "now — or --aperture D_MM,R_MM)",
            field="series",
        )
    return name


def session_scene(scene: Scene, series: str, aperture: tuple[float, float] | None = None) -> Scene:
    """``scene`` with the aperture (diameter, distance) [mm] of the new series ``series``
    where ``aperture`` is given (:func:`design_series` refuses one for a measured series)."""
    if aperture is None:
        return scene
    diameter, distance = aperture
    if not (0 < diameter < distance and math.isfinite(distance)):
        raise BadInputError(
            f"expected 0 < diameter < distance [mm], got {diameter:g}, {distance:g}",
            field="aperture",
        )
    geometry = SeriesGeometry(float(diameter), float(distance))
    return replace(scene, series={**scene.series, series: geometry})


def design_sample(measurements: Measurements, series: str) -> str:
    """The sample of ``series`` with the most rows (the one a new row is taken on); for a
    series without rows, the scene's sample with the most rows."""
    mask = measurements.series == series
    samples, counts = np.unique(
        measurements.sample[mask if np.any(mask) else slice(None)], return_counts=True
    )
    return str(samples[int(np.argmax(counts))])


def candidate_measurements(
    candidates: Candidates, measurements: Measurements, new_sample: bool = False
) -> Measurements:
    """The candidates as rows whose σ is the median relative σ of their series' rows (for a
    new series, the largest such median of the measured series: its noise is not known), on
    their series' sample with the most rows, or all on one new sample (``new_sample``)."""
    rows = candidates.as_measurements(measurements, new_sample)
    if measurements.reflectance_err is None:
        return rows
    relative = measurements.reflectance_err / measurements.reflectance
    median = {
        s: float(np.median(relative[measurements.series == s]))
        for s in dict.fromkeys(measurements.series)
    }
    widest = max(median.values())  # a new series: the noisiest measured series' (unknown)
    median = {s: median.get(s, widest) for s in set(rows.series)}
    error = np.array([median[s] for s in rows.series]) * rows.reflectance
    return Measurements(**{**rows.__dict__, "reflectance_err": error})


REACH_LIMITS = ("theta_i_deg", "theta_s_deg", "source_clearance_deg")


def reach_limit(settings: DesignSettings, theta_i, theta_s, phi_s) -> np.ndarray:
    """Per setting, the first limit of the instrument it breaks (:data:`REACH_LIMITS`:
    θi range, θs range, camera too near the beam), or ``""`` where it is reached."""
    theta_i, theta_s = np.asarray(theta_i, float), np.asarray(theta_s, float)
    in_plane = ~np.isfinite(np.asarray(phi_s, float))
    low_i, high_i = settings.theta_i_deg
    low_s, high_s = settings.theta_s_deg
    inside_i = (theta_i >= low_i - 1e-9) & (theta_i <= high_i + 1e-9)
    inside_s = np.where(
        in_plane, (theta_s >= low_s - 1e-9) & (theta_s <= high_s + 1e-9), theta_s <= high_s
    )
    clear = (np.abs(theta_i + theta_s) >= settings.source_clearance_deg - 1e-9) | ~in_plane
    return np.select([~inside_i, ~inside_s, ~clear], list(REACH_LIMITS), "")


def reachable(settings: DesignSettings, theta_i, theta_s, phi_s) -> np.ndarray:
    """True where the instrument reaches the setting (module docstring)."""
    return reach_limit(settings, theta_i, theta_s, phi_s) == ""


def _axis(step: float, low: float, high: float, limits: tuple[float, float]) -> np.ndarray:
    """The multiples of ``step`` in [low, high] [deg], with the reachable ``limits`` added."""
    first, last = math.ceil((low - 1e-9) / step), math.floor((high + 1e-9) / step)
    return np.unique(np.concatenate([step * np.arange(first, last + 1), limits]))


def grid_candidates(settings: DesignSettings, series: str) -> Candidates:
    """Every reachable in-plane setting of the grid (module docstring), in the given series;
    ``left_out`` counts the rest by the limit they break."""
    theta_i = _axis(settings.step_deg, 0.0, 89.0, settings.theta_i_deg)
    theta_s = _axis(settings.step_deg, -89.0, 89.0, settings.theta_s_deg)
    grid_i, grid_s = (a.reshape(-1) for a in np.meshgrid(theta_i, theta_s, indexing="ij"))
    phi = np.full(grid_i.shape, np.nan)
    limit = reach_limit(settings, grid_i, grid_s, phi)
    keep = limit == ""
    count = int(np.sum(keep))
    left_out = {"grid": int(limit.size), "reachable": count}
    left_out |= {name: int(np.sum(limit == name)) for name in REACH_LIMITS}
    return Candidates(
        np.full(count, series), grid_i[keep], grid_s[keep], phi[keep], left_out=left_out
    )


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
    known = set(measurements.series) | {series}
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
        limit = str(reach_limit(scene.design, *values))
        if limit:
            raise BadInputError(
                f"the instrument cannot reach θi = {values[0]:g}°, θs = {values[1]:g}° "
                f"([design] θi {list(scene.design.theta_i_deg)}, θs "
                f"{list(scene.design.theta_s_deg)}, camera ≥ "
                f"{scene.design.source_clearance_deg:g}° from the beam)",
                field="theta_s_deg" if limit == "source_clearance_deg" else limit,
                **where,
            )
        names.append(name)
        theta_i.append(values[0])
        theta_s.append(values[1])
        phi.append(values[2])
    if not names:
        raise BadInputError("no candidate rows", file=path)
    return Candidates(np.array(names), np.array(theta_i), np.array(theta_s), np.array(phi))


def check_budget(budget: int, candidates: int) -> None:
    """Refuse a budget above the candidates (one row per setting)."""
    if budget > candidates:
        raise BadInputError(
            f"a budget of {budget} rows, but {candidates} candidate settings (one row per setting)",
            field="budget",
        )
