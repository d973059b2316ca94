"""Generated measurement CSVs (both quantities, ``phi_s_deg``) and what a loaded table promises."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from hypothesis import strategies as st

from benchmarks._inputs import _LEVELS, _broken, _number_text, _scene_for_rows
from brdf_infer.tables.measurements import Measurements

_GOOD_CELLS: dict[str, st.SearchStrategy[str]] = {
    "series": st.sampled_from(["I", "II"]),
    "sample": st.sampled_from(["1", "2", "3", "a"]),
    "theta_i_deg": _number_text(0.0, 89.0, odd=False),
    "theta_s_deg": _number_text(-89.0, 89.0, odd=False),
    "reflectance": _number_text(1e-6, 0.5, odd=False),
    "reflectance_err": _number_text(0.0, 1e-3, odd=False),
    "brdf": _number_text(1e-4, 10.0, odd=False),
    "brdf_err": _number_text(0.0, 1.0, odd=False),
    "phi_s_deg": st.one_of(st.just(""), _number_text(0.0, 359.0, odd=False)),
}


_ODD_CELLS: dict[str, st.SearchStrategy[str]] = {
    "series": st.sampled_from(["III", "", " I ", "i", "I;II", '"I"', "I\x00"]),
    "sample": st.sampled_from(["", "1.0", "x y", "\t"]),
    "theta_i_deg": _number_text(-90.0, 180.0),
    "theta_s_deg": _number_text(-180.0, 180.0),
    "reflectance": _number_text(-1.0, 2.0),
    "reflectance_err": _number_text(-1.0, 1.0),
    "brdf": _number_text(-1.0, 1e6),
    "brdf_err": _number_text(-1.0, 1.0),
    "phi_s_deg": _number_text(-360.0, 720.0),
}


_ENCODINGS = ["utf-8", "utf-8-sig", "latin-1", "utf-16", "cp1252", "ascii"]


@dataclass(frozen=True)
class CsvInput:
    """A measurement CSV and the scene it is read for (each series' quantity)."""

    data: bytes
    series_quantity: dict[str, str]

    def describe(self) -> str:
        return f"series {self.series_quantity}, CSV bytes {self.data[:400]!r}"


@st.composite
def measurement_csvs(draw) -> CsvInput:
    """A measurement table, well-formed or broken in one or more ways."""
    level = draw(_LEVELS)
    brdf = draw(st.booleans())
    value, error = ("brdf", "brdf_err") if brdf else ("reflectance", "reflectance_err")
    columns = ["series", "sample", "theta_i_deg", "theta_s_deg", value]
    columns += [error] if draw(st.booleans()) else []
    columns += ["phi_s_deg"] if draw(st.booleans()) else []
    columns = draw(st.permutations(columns))
    if _broken(draw, level, 6):  # a column missing, doubled, renamed, of the other quantity
        k = draw(st.integers(0, len(columns) - 1))
        columns = draw(
            st.sampled_from(
                [
                    columns[:k] + columns[k + 1 :],
                    [*columns, columns[k]],
                    [*columns[:k], columns[k].upper(), *columns[k + 1 :]],
                    [*columns, "brdf" if not brdf else "reflectance"],
                ]
            )
        )
    header = list(columns)
    if draw(st.integers(0, 3)) == 0:  # extra columns are ignored
        header.append(draw(st.sampled_from(["note", " comment ", "x y"])))
    rows, keys = [], set()
    for _ in range(draw(st.integers(1, 6)) - _broken(draw, level, 8)):
        row = []
        for name in header:
            odd = _broken(draw, level, 12)
            cells = _ODD_CELLS if odd else _GOOD_CELLS
            row.append(draw(cells.get(name, st.text(st.characters(codec="ascii"), max_size=4))))
        if _broken(draw, level, 10):  # too many or too few cells
            row = [*row, "7"] if draw(st.booleans()) else row[:-1]
        identity = ("series", "sample", "theta_i_deg", "theta_s_deg", "phi_s_deg")
        key = tuple(cell for cell, name in zip(row, header, strict=False) if name in identity)
        if key not in keys or _broken(draw, level, 2):  # duplicates only when broken
            rows.append(row)
            keys.add(key)
    if rows and _broken(draw, level, 8):
        rows.insert(draw(st.integers(0, len(rows))), list(draw(st.sampled_from(rows))))
    delimiter = draw(st.sampled_from([";", "\t", " , "])) if _broken(draw, level, 8) else ","
    quote = draw(st.integers(0, 5)) == 0  # quoted cells are fine

    def line(cells: list[str]) -> str:
        return delimiter.join(f'"{c}"' if quote else c for c in cells)

    lines = [line(header), *(line(r) for r in rows)]
    if draw(st.integers(0, 5)) == 0:  # blank lines are skipped; a comment line is a row
        blank = draw(st.sampled_from(["", "  ", "# note"] if level else ["", "  "]))
        lines.insert(draw(st.integers(1 if level == 0 else 0, len(lines))), blank)
    newline = draw(st.sampled_from(["\n", "\r\n", "\r"]))
    text = newline.join(lines) + draw(st.sampled_from([newline, "", newline * 3]))
    encoding = draw(st.sampled_from(_ENCODINGS if level else ["utf-8", "utf-8-sig"]))
    data = text.encode(encoding, errors="replace")
    if _broken(draw, level, 8):  # bytes broken: truncated, a NUL, invalid UTF-8
        cut = draw(st.integers(0, len(data)))
        data = draw(
            st.sampled_from([data[:cut], data[:cut] + b"\x00" + data[cut:], data + b"\xff"])
        )
    quantity = "brdf" if brdf else "raw_reflectance"
    other = st.sampled_from(["raw_reflectance", "brdf"])
    quantities = {
        name: quantity if not _broken(draw, level, 8) else draw(other) for name in ["I", "II"]
    }
    return CsvInput(data, quantities)


def _write_csv(folder: Path, given: CsvInput) -> Path:
    path = folder / "m.csv"
    path.write_bytes(given.data)
    return path


def _read_csv(path: Path, given: CsvInput) -> Measurements:
    """Read a generated CSV as the scene's loader does."""
    from brdf_infer.tables.measurements import load_measurements

    return load_measurements(path, given.series_quantity, given.series_quantity)


def check_measurements(rows: Measurements, known: set[str] | None = None) -> None:
    """What a loaded table promises (the CSV loader's checks): raises AssertionError."""
    n = len(rows)
    assert n >= 1
    arrays = [rows.series, rows.sample, rows.theta_i_deg, rows.theta_s_deg, rows.reflectance]
    assert all(len(a) == n for a in arrays)
    assert all(str(s) for s in rows.series) and all(str(s) for s in rows.sample)
    assert known is None or set(rows.series.tolist()) <= known
    assert np.all(np.isfinite(rows.theta_i_deg)) and np.all(np.isfinite(rows.theta_s_deg))
    assert np.all((rows.theta_i_deg >= 0) & (rows.theta_i_deg < 90)), rows.theta_i_deg
    assert np.all(np.abs(rows.theta_s_deg) <= 90), rows.theta_s_deg
    assert np.all(np.isfinite(rows.reflectance)) and np.all(rows.reflectance > 0)
    if rows.quantity == "raw_reflectance":
        assert np.all(rows.reflectance < 1)
    if rows.reflectance_err is not None:
        assert len(rows.reflectance_err) == n
        assert np.all(np.isfinite(rows.reflectance_err)) and np.all(rows.reflectance_err >= 0)
    if rows.phi_s_deg is not None:
        phi = rows.phi_s_deg[np.isfinite(rows.phi_s_deg)]
        assert np.all((phi > 0) & (phi < 360)) and np.all(rows.theta_s_deg[rows.out_of_plane] >= 0)
    phi = np.full(n, np.nan) if rows.phi_s_deg is None else rows.phi_s_deg
    keys = {
        (s, m, t, u, "in-plane" if math.isnan(p) else p)
        for s, m, t, u, p in zip(
            rows.series, rows.sample, rows.theta_i_deg, rows.theta_s_deg, phi, strict=True
        )
    }
    assert len(keys) == n, "duplicate rows"


def _csv_command(path: Path, given: CsvInput) -> list[str]:
    return ["fit", _scene_for_rows(path, path.name, given.series_quantity), "--method", "paper"]
