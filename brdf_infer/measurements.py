"""Measurement table: one validated row per raw-reflectance measurement.

Columns (header required, extra named columns ignored):
``series,sample,theta_i_deg,theta_s_deg,reflectance`` and, optionally, ``reflectance_err``
(the 1σ of each value; without it the scene's ``errors.reflectance_rel`` stands in).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from brdf_infer.errors import BadInputError

COLUMNS: tuple[str, ...] = (
    "series",
    "sample",
    "theta_i_deg",
    "theta_s_deg",
    "reflectance",
    "reflectance_err",
)
REQUIRED_COLUMNS: tuple[str, ...] = COLUMNS[:5]


@dataclass(frozen=True)
class Measurements:
    """A validated measurement table (numpy arrays of equal length, one entry per row).

    Attributes:
        path: the CSV file the rows came from.
        series: name of the measurement series (geometry) of each row.
        sample: name of the physical sample of each row.
        theta_i_deg: incidence angle θi [deg].
        theta_s_deg: in-plane scattering angle θs [deg] (> 0: forward side).
        reflectance: raw reflectance R of Eq. (2) [-].
        reflectance_err: 1σ uncertainty of R [-], or None when the file has no such column.
    """

    path: Path
    series: np.ndarray
    sample: np.ndarray
    theta_i_deg: np.ndarray
    theta_s_deg: np.ndarray
    reflectance: np.ndarray
    reflectance_err: np.ndarray | None

    def __len__(self) -> int:
        return len(self.series)

    def subset(self, mask: np.ndarray) -> Measurements:
        """The rows where ``mask`` is true."""
        return Measurements(
            path=self.path,
            series=self.series[mask],
            sample=self.sample[mask],
            theta_i_deg=self.theta_i_deg[mask],
            theta_s_deg=self.theta_s_deg[mask],
            reflectance=self.reflectance[mask],
            reflectance_err=None if self.reflectance_err is None else self.reflectance_err[mask],
        )


def _check_range(value: float, field: str, where: dict) -> None:
    if field == "reflectance" and not 0.0 < value < 1.0:
        raise BadInputError(f"raw reflectance must lie in (0, 1), got {value}", **where)
    if field == "reflectance_err" and value < 0.0:
        raise BadInputError(f"uncertainty must be >= 0, got {value}", **where)
    if field == "theta_i_deg" and not 0.0 <= value < 90.0:
        raise BadInputError(f"incidence angle must lie in [0, 90) deg, got {value}", **where)
    if field == "theta_s_deg" and not -90.0 <= value <= 90.0:
        raise BadInputError(f"scattering angle must lie in [-90, 90] deg, got {value}", **where)


def _parse_number(text: str, field: str, where: dict) -> float:
    try:
        value = float(text)
    except ValueError:
        raise BadInputError(f"not a number: {text!r}", **where) from None
    if not math.isfinite(value):
        raise BadInputError(f"not a finite number: {text!r}", **where)
    _check_range(value, field, where)
    return value


def _read_rows(path: Path) -> tuple[list[str], list[tuple[int, list[str]]]]:
    """Header and (line number, cells) of every non-blank row."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except IsADirectoryError:
        raise BadInputError("is a directory, not a CSV file", file=path) from None
    except FileNotFoundError:
        raise BadInputError("no such file", file=path) from None
    except (OSError, UnicodeDecodeError) as error:
        raise BadInputError(f"cannot read: {error}", file=path) from None
    reader = csv.reader(text.splitlines())
    rows = [(reader.line_num, cells) for cells in reader if any(c.strip() for c in cells)]
    if not rows:
        raise BadInputError("empty file: expected a header and measurement rows", file=path)
    header = rows[0][1]
    return [name.strip() for name in header], rows[1:]


def load_measurements(path: str | Path, known_series: Iterable[str] | None = None) -> Measurements:
    """Read and validate a measurement CSV.

    Args:
        path: the CSV file.
        known_series: the series the scene defines; rows naming others are rejected.

    Returns:
        The validated table.

    Raises:
        BadInputError: unreadable or empty file, missing or duplicated header columns, a row
            with more cells than the header, an empty or non-numeric cell, NaN/inf, R outside
            (0, 1), negative σ, θi outside [0, 90), θs outside [−90, 90], an unknown series,
            or a duplicated (series, sample, θi, θs) row. The message names file, row, field.
    """
    path = Path(path)
    header, rows = _read_rows(path)
    for position, name in enumerate(header):
        if not name:
            raise BadInputError(f"header column {position + 1} has no name", file=path, line=1)
        if header.count(name) > 1:
            raise BadInputError("column appears twice in the header", file=path, field=name)
    for name in REQUIRED_COLUMNS:
        if name not in header:
            raise BadInputError(
                "missing header column (expected " + ",".join(REQUIRED_COLUMNS) + " and "
                "optionally reflectance_err)" + _delimiter_hint(header),
                file=path,
                field=name,
            )
    if not rows:
        raise BadInputError("no measurement rows after the header", file=path)
    columns = [name for name in COLUMNS if name in header]
    index = {name: header.index(name) for name in columns}
    known = None if known_series is None else set(known_series)
    parsed: dict[str, list] = {name: [] for name in columns}
    seen: dict[tuple, int] = {}
    for row_number, (line, cells) in enumerate(rows, start=1):
        if len(cells) > len(header):
            raise BadInputError(
                f"{len(cells)} cells but the header names {len(header)} columns",
                file=path,
                row=row_number,
                line=line,
            )
        record = {}
        for name in columns:
            where = {"file": path, "row": row_number, "line": line, "field": name}
            position = index[name]
            text = cells[position].strip() if position < len(cells) else ""
            if not text:
                raise BadInputError("empty cell", **where)
            record[name] = (
                text if name in ("series", "sample") else _parse_number(text, name, where)
            )
        if known is not None and record["series"] not in known:
            raise BadInputError(
                f"series {record['series']!r} is not defined in the scene "
                f"(defined: {', '.join(sorted(known))})",
                file=path,
                row=row_number,
                line=line,
                field="series",
            )
        key = tuple(record[name] for name in COLUMNS[:4])
        if key in seen:
            raise BadInputError(
                f"duplicate of row {seen[key]} (same series, sample, theta_i_deg, theta_s_deg)",
                file=path,
                row=row_number,
                line=line,
            )
        seen[key] = row_number
        for name in columns:
            parsed[name].append(record[name])
    return Measurements(
        path=path,
        series=np.asarray(parsed["series"], dtype=str),
        sample=np.asarray(parsed["sample"], dtype=str),
        theta_i_deg=np.asarray(parsed["theta_i_deg"], dtype=float),
        theta_s_deg=np.asarray(parsed["theta_s_deg"], dtype=float),
        reflectance=np.asarray(parsed["reflectance"], dtype=float),
        reflectance_err=(
            np.asarray(parsed["reflectance_err"], dtype=float)
            if "reflectance_err" in parsed
            else None
        ),
    )


def _delimiter_hint(header: list[str]) -> str:
    """A hint when the header looks like another delimiter than the comma was used."""
    joined = ",".join(header)
    for delimiter, name in ((";", "semicolons"), ("\t", "tabs")):
        if delimiter in joined:
            return f"; the header seems to use {name}: separate the columns with commas"
    return ""
