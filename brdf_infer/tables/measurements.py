"""Measurement table: one validated row per measurement.

Columns (header required, extra named columns ignored):
``series,sample,theta_i_deg,theta_s_deg,reflectance`` and, optionally, ``reflectance_err``
(the 1σ of each value; without it the scene's ``errors.reflectance_rel`` stands in) for raw
reflectance through an aperture (Eq. 2); ``brdf`` and ``brdf_err`` [sr⁻¹] in place of the last
two for BRDF values (a scatterometer's output, no aperture to convert through).

An optional ``phi_s_deg`` column places a row out of the plane of incidence: θs is then the
polar angle θ ∈ [0°, 90°] and φs the azimuth in the paper's frame (forward-scattering plane at
180°, Sec. 4.1). A row with an empty ``phi_s_deg`` cell is in the plane with a signed θs as
always; a row at φs = 180° (0°) is the in-plane row at +θ (−θ).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from brdf_infer.errors import BadInputError
from brdf_infer.tables.screening import TableScreening

COLUMNS: tuple[str, ...] = (
    "series",
    "sample",
    "theta_i_deg",
    "theta_s_deg",
    "reflectance",
    "reflectance_err",
)
REQUIRED_COLUMNS: tuple[str, ...] = COLUMNS[:5]
BRDF_COLUMNS: tuple[str, ...] = (*COLUMNS[:4], "brdf", "brdf_err")
QUANTITIES: tuple[str, ...] = ("raw_reflectance", "brdf")


@dataclass(frozen=True)
class Measurements:
    """A validated measurement table (numpy arrays of equal length, one entry per row).

    Attributes:
        path: the CSV file the rows came from.
        series: name of the measurement series (geometry) of each row.
        sample: name of the physical sample of each row.
        theta_i_deg: incidence angle θi [deg].
        theta_s_deg: in-plane scattering angle θs [deg] (> 0: forward side).
        reflectance: the measured value: raw reflectance R of Eq. (2) [-] or, for a
            ``brdf`` table, BRDF [sr⁻¹].
        reflectance_err: 1σ uncertainty of the value, or None when the file has no such column.
        quantity: ``raw_reflectance`` or ``brdf`` (from the columns of the file).
        phi_s_deg: azimuth of each out-of-plane row [deg] (NaN for in-plane rows), or None
            when every row is in the plane.
        screening: what reading a .BSDF table left out, counted by its rules
            (:class:`brdf_infer.tables.screening.TableScreening`); None for a CSV.
    """

    path: Path
    series: np.ndarray
    sample: np.ndarray
    theta_i_deg: np.ndarray
    theta_s_deg: np.ndarray
    reflectance: np.ndarray
    reflectance_err: np.ndarray | None
    quantity: str = "raw_reflectance"
    phi_s_deg: np.ndarray | None = None
    screening: TableScreening | None = None

    @property
    def out_of_plane(self) -> np.ndarray:
        """True for the rows out of the plane of incidence."""
        if self.phi_s_deg is None:
            return np.zeros(len(self.series), bool)
        return np.isfinite(self.phi_s_deg)

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
            quantity=self.quantity,
            phi_s_deg=None if self.phi_s_deg is None else self.phi_s_deg[mask],
            screening=self.screening,
        )


def _check_range(value: float, field: str, where: dict) -> None:
    if field == "reflectance" and not 0.0 < value < 1.0:
        raise BadInputError(f"raw reflectance must lie in (0, 1), got {value}", **where)
    if field == "brdf" and not value > 0.0:
        raise BadInputError(f"BRDF must be > 0 sr^-1, got {value}", **where)
    if field in ("reflectance_err", "brdf_err") and value < 0.0:
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
    if "\x00" in text:  # names would lose it (NumPy strips trailing NULs): rows would merge
        line = text.count("\n", 0, text.index("\x00")) + 1
        raise BadInputError(
            "contains a NUL character (a binary file, or UTF-16? save it as UTF-8 text)",
            file=path,
            line=line,
        )
    reader = csv.reader(text.splitlines())
    rows = [(reader.line_num, cells) for cells in reader if any(c.strip() for c in cells)]
    if not rows:
        raise BadInputError("empty file: expected a header and measurement rows", file=path)
    header = rows[0][1]
    return [name.strip() for name in header], rows[1:]


def _table_columns(header: list[str], path: Path) -> tuple[str, tuple[str, ...]]:
    """The table's quantity and its value columns, from the header."""
    if "reflectance" in header and "brdf" in header:
        raise BadInputError(
            "a table holds one quantity: both reflectance and brdf columns", file=path, field="brdf"
        )
    quantity = "brdf" if "brdf" in header else "raw_reflectance"
    columns = BRDF_COLUMNS if quantity == "brdf" else COLUMNS
    for name in columns[:5]:
        if name not in header:
            raise BadInputError(
                "missing header column (expected " + ",".join(REQUIRED_COLUMNS) + " and "
                "optionally reflectance_err, or brdf,brdf_err for BRDF values; optionally "
                "phi_s_deg)" + _delimiter_hint(header),
                file=path,
                field=name,
            )
    return quantity, columns


def _cell(cells: list[str], position: int) -> str:
    return cells[position].strip() if position < len(cells) else ""


def _azimuth(text: str, theta_s: float, where: dict) -> tuple[float, float]:
    """(θs, φs) of a row with a ``phi_s_deg`` cell: in-plane rows (empty cell, φ = 0° or 180°)
    get a signed θs and φs = NaN."""
    if not text:
        return theta_s, math.nan
    phi = _parse_number(text, "phi_s_deg", where)
    if not 0.0 <= theta_s <= 90.0:
        raise BadInputError(
            f"with phi_s_deg, theta_s_deg is the polar angle in [0, 90] deg, got {theta_s}",
            **{**where, "field": "theta_s_deg"},
        )
    phi = phi % 360.0
    if phi == 180.0:
        return theta_s, math.nan
    if phi == 0.0:
        return -theta_s, math.nan
    return theta_s, phi


# joins a campaign's name to the names of its series and samples in a pooled scene ("labA/II")
CAMPAIGN_SEPARATOR = "/"


def pooled_measurements(parts: dict[str, tuple[Measurements, float]]) -> Measurements:
    """The rows of several campaigns as one table, in the campaigns' order: each campaign's
    series and samples named ``CAMPAIGN/NAME`` (so no two campaigns share a series or a
    sample). ``parts``: campaign name → (its rows, its ``reflectance_rel``): a campaign whose
    file has no ``reflectance_err`` column gets σ = reflectance_rel × value, which is what its
    own error settings give it (:func:`brdf_infer.model.error_model.value_sigma`).

    Raises:
        BadInputError: the campaigns measure different quantities (raw reflectance, BRDF).
    """
    tables = [rows for rows, _ in parts.values()]
    quantities = {rows.quantity for rows in tables}
    if len(quantities) > 1:
        raise BadInputError(
            f"the campaigns of one scene measure one quantity, got {sorted(quantities)}",
            file=tables[-1].path,
            field="quantity",
        )

    def joined(get) -> np.ndarray:
        return np.concatenate([np.asarray(get(name, rows)) for name, (rows, _) in parts.items()])

    with_errors = any(rows.reflectance_err is not None for rows in tables)
    out_of_plane = any(rows.phi_s_deg is not None for rows in tables)
    return Measurements(
        path=tables[0].path,
        series=joined(lambda name, rows: [f"{name}{CAMPAIGN_SEPARATOR}{s}" for s in rows.series]),
        sample=joined(lambda name, rows: [f"{name}{CAMPAIGN_SEPARATOR}{s}" for s in rows.sample]),
        theta_i_deg=joined(lambda _, rows: rows.theta_i_deg),
        theta_s_deg=joined(lambda _, rows: rows.theta_s_deg),
        reflectance=joined(lambda _, rows: rows.reflectance),
        reflectance_err=None
        if not with_errors
        else joined(
            lambda name, rows: (
                rows.reflectance_err
                if rows.reflectance_err is not None
                else parts[name][1] * rows.reflectance
            )
        ),
        quantity=quantities.pop(),
        phi_s_deg=None
        if not out_of_plane
        else joined(
            lambda _, rows: (
                rows.phi_s_deg if rows.phi_s_deg is not None else np.full(len(rows), math.nan)
            )
        ),
    )


def load_measurements(
    path: str | Path,
    known_series: Iterable[str] | None = None,
    series_quantity: dict[str, str] | None = None,
) -> Measurements:
    """Read and validate a measurement CSV.

    Args:
        path: the CSV file.
        known_series: the series the scene defines; rows naming others are rejected.
        series_quantity: each series' measured quantity; rows of a series whose quantity is
            not the table's are rejected.

    Returns:
        The validated table.

    Raises:
        BadInputError: unreadable or empty file, missing or duplicated header columns, a row
            with more cells than the header, an empty or non-numeric cell, NaN/inf, R outside
            (0, 1), BRDF ≤ 0, negative σ, θi outside [0, 90), θs outside [−90, 90] (or
            [0, 90] with an azimuth), an unknown series or one of another quantity, or a
            duplicated row. The message names file, row, field.
    """
    path = Path(path)
    header, rows = _read_rows(path)
    _check_header(header, path)
    quantity, table_columns = _table_columns(header, path)
    if not rows:
        raise BadInputError("no measurement rows after the header", file=path)
    columns = [name for name in table_columns if name in header]
    value, error = table_columns[4], table_columns[5]
    index = {name: header.index(name) for name in (*columns, "phi_s_deg") if name in header}
    known = None if known_series is None else set(known_series)
    parsed: dict[str, list] = {name: [] for name in (*columns, "phi_s_deg")}
    seen: dict[tuple, int] = {}
    for row_number, (line, cells) in enumerate(rows, start=1):
        at = {"file": path, "row": row_number, "line": line}
        record = _parse_row(cells, len(header), columns, index, at)
        _check_series(record, known, series_quantity or {}, quantity, {**at, "field": value})
        key = (*(record[name] for name in COLUMNS[:4]), record["phi_s_deg"])
        key = tuple("in-plane" if isinstance(k, float) and math.isnan(k) else k for k in key)
        if key in seen:
            raise BadInputError(
                f"duplicate of row {seen[key]} (same series, sample, theta_i_deg, theta_s_deg"
                + (", phi_s_deg)" if "phi_s_deg" in index else ")"),
                **at,
            )
        seen[key] = row_number
        for name in (*columns, "phi_s_deg"):
            if name in record:
                parsed[name].append(record[name])
    phi = np.asarray(parsed["phi_s_deg"], dtype=float)
    return Measurements(
        path=path,
        series=np.asarray(parsed["series"], dtype=str),
        sample=np.asarray(parsed["sample"], dtype=str),
        theta_i_deg=np.asarray(parsed["theta_i_deg"], dtype=float),
        theta_s_deg=np.asarray(parsed["theta_s_deg"], dtype=float),
        reflectance=np.asarray(parsed[value], dtype=float),
        reflectance_err=np.asarray(parsed[error], dtype=float) if error in parsed else None,
        quantity=quantity,
        phi_s_deg=phi if np.any(np.isfinite(phi)) else None,
    )


def header_quantity(path: str | Path) -> str | None:
    """The quantity a CSV's header names (``brdf`` or ``raw_reflectance``), read from its first
    non-blank line only; None where the file cannot be read or the header names neither (or
    both): :func:`load_measurements` then says what is wrong."""
    names: set[str] = set()
    try:
        with Path(path).open(encoding="utf-8-sig", newline="") as handle:
            for cells in csv.reader(handle):
                names = {cell.strip() for cell in cells} - {""}
                if names:
                    break
    except (OSError, UnicodeDecodeError, csv.Error):
        return None
    if ("brdf" in names) == ("reflectance" in names):
        return None
    return "brdf" if "brdf" in names else "raw_reflectance"


def _check_header(header: list[str], path: Path) -> None:
    """Every header column named, and named once."""
    for position, name in enumerate(header):
        if not name:
            raise BadInputError(f"header column {position + 1} has no name", file=path, line=1)
        if header.count(name) > 1:
            raise BadInputError("column appears twice in the header", file=path, field=name)


def _parse_row(
    cells: list[str], width: int, columns: list[str], index: dict[str, int], at: dict
) -> dict:
    """One row's values by column, θs signed and φs NaN for an in-plane row (:func:`_azimuth`).

    Args:
        cells: the row's cells.
        width: the number of header columns.
        columns: the table's columns present in the header, ``phi_s_deg`` aside.
        index: each column's position in the header, ``phi_s_deg`` included if present.
        at: the row's file, row and line for an error.
    """
    if len(cells) > width:
        raise BadInputError(f"{len(cells)} cells but the header names {width} columns", **at)
    record = {}
    for name in columns:
        where = {**at, "field": name}
        text = _cell(cells, index[name])
        if not text:
            raise BadInputError("empty cell", **where)
        record[name] = text if name in ("series", "sample") else _parse_number(text, name, where)
    where = {**at, "field": "phi_s_deg"}
    record["theta_s_deg"], record["phi_s_deg"] = _azimuth(
        _cell(cells, index["phi_s_deg"]) if "phi_s_deg" in index else "",
        record["theta_s_deg"],
        where,
    )
    return record


def _check_series(
    record: dict, known: set[str] | None, series_quantity: dict[str, str], quantity: str, at: dict
) -> None:
    """A row's series is one the scene defines (``known``), measuring the table's quantity;
    ``at`` names the row and the value column."""
    if known is not None and record["series"] not in known:
        raise BadInputError(
            f"series {record['series']!r} is not defined in the scene "
            f"(defined: {', '.join(sorted(known))})",
            **{**at, "field": "series"},
        )
    expected = series_quantity.get(record["series"], quantity)
    if expected != quantity:
        raise BadInputError(
            f"series {record['series']!r} measures {expected} but this table holds "
            f'{quantity} values (set quantity = "{quantity}" in the scene\'s '
            f"[series.{record['series']}]?)",
            **at,
        )


def _delimiter_hint(header: list[str]) -> str:
    """A hint when the header looks like another delimiter than the comma was used."""
    joined = ",".join(header)
    for delimiter, name in ((";", "semicolons"), ("\t", "tabs")):
        if delimiter in joined:
            return f"; the header seems to use {name}: separate the columns with commas"
    return ""
