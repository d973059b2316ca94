"""Independent (clean-room) oracle for Zemax/Radiant tabular ``.BSDF`` files.

Derived only from the written spec of the "BSDF Data Interchange" tabular format; it does not
import anything from the package's own exporter.  Uses numpy and the standard library only.

Provides a strict reader (:func:`read_bsdf`), a writer-strictness checker
(:func:`strictness_problems`), the specular-frame -> model-frame geometry
(:func:`specular_frame_to_model`) and a hemisphere integral of one incidence's table
(:func:`hemisphere_integral`).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

__all__ = [
    "hemisphere_integral",
    "read_bsdf",
    "specular_frame_to_model",
    "strictness_problems",
]

# The spec's formatting notes: "There is currently only one option for the Source variable:
# Measured" (no value exists for model-derived tables).
_SOURCES = {"measured": "Measured"}
_SYMMETRIES = {"planesymmetrical": "PlaneSymmetrical", "asymmetrical": "Asymmetrical"}
_SCATTER_TYPES = {"brdf": "BRDF", "btdf": "BTDF"}
_COUNT_KEYWORDS = ("SampleRotation", "AngleOfIncidence", "ScatterAzimuth", "ScatterRadial")
_NUMBER_RE = re.compile(r"^[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?$")


# --------------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------------


def _read_lines(path: str | Path) -> list[str]:
    """Return the file's lines without their line terminators."""
    return Path(path).read_text(encoding="utf-8").splitlines()


def _is_comment(line: str) -> bool:
    return line.lstrip().startswith("#")


def _float(token: str, lineno: int) -> float:
    """Parse one finite decimal number or raise ``ValueError`` naming the line."""
    if not _NUMBER_RE.match(token):
        raise ValueError(f"line {lineno}: not a number: {token!r}")
    value = float(token)
    if not math.isfinite(value):
        raise ValueError(f"line {lineno}: non-finite number: {token!r}")
    return value


class _Cursor:
    """Walks the significant (non-blank, non-comment) lines, collecting comments."""

    def __init__(self, lines: list[str]) -> None:
        self.items: list[tuple[int, str]] = []
        self.comments: list[str] = []
        for i, raw in enumerate(lines, start=1):
            if _is_comment(raw):
                self.comments.append(raw.lstrip()[1:].strip())
            elif raw.strip():
                self.items.append((i, raw.strip()))
        self.pos = 0
        self.last_lineno = len(lines)

    def next(self, what: str) -> tuple[int, list[str]]:
        """Return (line number, whitespace-split tokens) of the next significant line."""
        if self.pos >= len(self.items):
            raise ValueError(f"line {self.last_lineno}: unexpected end of file, expected {what}")
        lineno, text = self.items[self.pos]
        self.pos += 1
        return lineno, text.split()

    def peek_keyword(self) -> str | None:
        if self.pos >= len(self.items):
            return None
        return self.items[self.pos][1].split()[0].lower()


def _keyword_value(cur: _Cursor, keyword: str, allowed: dict[str, str]) -> str:
    """Read a ``Keyword Value`` header line and return the canonical value."""
    lineno, tokens = cur.next(keyword)
    if tokens[0].lower() != keyword.lower():
        raise ValueError(f"line {lineno}: expected {keyword!r}, found {tokens[0]!r}")
    if len(tokens) != 2:
        raise ValueError(f"line {lineno}: {keyword} needs exactly one value, got {tokens[1:]}")
    value = tokens[1].lower()
    if keyword == "SpectralContent" and value == "tristimulus":
        raise ValueError(f"line {lineno}: Tristimulus spectral content is not supported")
    if value not in allowed:
        raise ValueError(f"line {lineno}: bad {keyword} value {tokens[1]!r}")
    return allowed[value]


def _count_and_values(cur: _Cursor, keyword: str) -> tuple[np.ndarray, int]:
    """Read ``Keyword N`` plus a line of exactly N numbers; return (values, their line)."""
    lineno, tokens = cur.next(keyword)
    if tokens[0].lower() != keyword.lower():
        raise ValueError(f"line {lineno}: expected {keyword!r}, found {tokens[0]!r}")
    if len(tokens) != 2 or not re.fullmatch(r"\+?\d+", tokens[1]):
        raise ValueError(f"line {lineno}: {keyword} needs one integer count, got {tokens[1:]}")
    count = int(tokens[1])
    if count < 1:
        raise ValueError(f"line {lineno}: {keyword} count must be >= 1, got {count}")
    vlineno, values = cur.next(f"{count} {keyword} values")
    if len(values) != count:
        raise ValueError(f"line {vlineno}: {keyword} announced {count} values, found {len(values)}")
    return np.array([_float(v, vlineno) for v in values], dtype=float), vlineno


def _check_axis(name: str, axis: tuple[np.ndarray, int], lo: float, hi: float) -> None:
    values, lineno = axis
    if np.any(np.diff(values) <= 0):
        raise ValueError(f"line {lineno}: {name} values must be strictly increasing: {values}")
    if values.min() < lo or values.max() > hi:
        raise ValueError(f"line {lineno}: {name} values must lie in [{lo}, {hi}]: {values}")


def read_bsdf(path: str | Path) -> dict:
    """Parse a monochrome tabular ``.BSDF`` file strictly.

    Returns a dict with ``symmetry``, ``scatter_type``, ``sample_rotation``,
    ``angle_of_incidence``, ``scatter_azimuth``, ``scatter_radial`` (deg arrays), ``tis``
    (n_rotation, n_aoi), ``bsdf`` (n_rotation, n_aoi, n_azimuth, n_radial) and ``comments``
    (comment texts without the leading ``#``, whitespace-stripped).  Raises ``ValueError``
    naming the line number on anything malformed.
    """
    cur = _Cursor(_read_lines(path))
    _keyword_value(cur, "Source", _SOURCES)
    symmetry = _keyword_value(cur, "Symmetry", _SYMMETRIES)
    _keyword_value(cur, "SpectralContent", {"monochrome": "Monochrome"})
    scatter_type = _keyword_value(cur, "ScatterType", _SCATTER_TYPES)
    axes = {kw: _count_and_values(cur, kw) for kw in _COUNT_KEYWORDS}

    _check_axis("AngleOfIncidence", axes["AngleOfIncidence"], 0.0, 90.0)
    _check_axis("ScatterRadial", axes["ScatterRadial"], 0.0, 180.0)
    az_hi = 180.0 if symmetry == "PlaneSymmetrical" else 360.0
    _check_axis("ScatterAzimuth", axes["ScatterAzimuth"], 0.0, az_hi)
    sizes = {kw: values.size for kw, (values, _) in axes.items()}

    lineno, tokens = cur.next("Monochrome")
    if tokens[0].lower() == "tristimulus":
        raise ValueError(f"line {lineno}: Tristimulus data is not supported")
    if [t.lower() for t in tokens] != ["monochrome"]:
        raise ValueError(f"line {lineno}: expected 'Monochrome', found {' '.join(tokens)!r}")
    lineno, tokens = cur.next("DataBegin")
    if [t.lower() for t in tokens] != ["databegin"]:
        raise ValueError(f"line {lineno}: expected 'DataBegin', found {' '.join(tokens)!r}")

    n_rot, n_aoi, n_az, n_rad = (sizes[kw] for kw in _COUNT_KEYWORDS)
    tis = np.empty((n_rot, n_aoi))
    bsdf = np.empty((n_rot, n_aoi, n_az, n_rad))
    for i_rot in range(n_rot):
        for i_aoi in range(n_aoi):
            where = f"TIS line for rotation #{i_rot + 1}, AOI #{i_aoi + 1}"
            lineno, tokens = cur.next(where)
            if tokens[0].lower() == "dataend":
                raise ValueError(f"line {lineno}: DataEnd before all tables were read ({where})")
            if tokens[0].lower() != "tis":
                raise ValueError(f"line {lineno}: missing {where}, found {tokens[0]!r}")
            if len(tokens) != 2:
                raise ValueError(f"line {lineno}: TIS line needs exactly one value")
            tis[i_rot, i_aoi] = _float(tokens[1], lineno)
            for i_az in range(n_az):
                lineno, tokens = cur.next(f"data row {i_az + 1} of {n_az}")
                if tokens[0].lower() in ("tis", "dataend"):
                    raise ValueError(
                        f"line {lineno}: expected data row {i_az + 1} of {n_az}, "
                        f"found {tokens[0]!r}"
                    )
                if len(tokens) != n_rad:
                    raise ValueError(
                        f"line {lineno}: data row has {len(tokens)} values, expected {n_rad}"
                    )
                bsdf[i_rot, i_aoi, i_az] = [_float(t, lineno) for t in tokens]

    lineno, tokens = cur.next("DataEnd")
    if [t.lower() for t in tokens] != ["dataend"]:
        raise ValueError(f"line {lineno}: expected 'DataEnd', found {' '.join(tokens)!r}")
    if cur.pos < len(cur.items):
        extra_lineno = cur.items[cur.pos][0]
        raise ValueError(f"line {extra_lineno}: unexpected content after DataEnd")
    if np.any(bsdf < 0) or np.any(tis < 0):
        raise ValueError("data block: negative BSDF or TIS value")

    return {
        "symmetry": symmetry,
        "scatter_type": scatter_type,
        "sample_rotation": axes["SampleRotation"][0],
        "angle_of_incidence": axes["AngleOfIncidence"][0],
        "scatter_azimuth": axes["ScatterAzimuth"][0],
        "scatter_radial": axes["ScatterRadial"][0],
        "tis": tis,
        "bsdf": bsdf,
        "comments": cur.comments,
    }


# --------------------------------------------------------------------------------------------
# strictness
# --------------------------------------------------------------------------------------------


def significant_digits(token: str) -> int:
    """Significant digits of a written decimal number (``1.2345e-03`` -> 5, ``0.012345`` -> 5).

    Leading zeros are not significant; every digit after the first non-zero one is (including
    trailing zeros).  Exact zero returns 0.
    """
    mantissa = re.split(r"[eE]", token.strip().lstrip("+-"), maxsplit=1)[0]
    digits = mantissa.replace(".", "").lstrip("0")
    return len(digits)


def _separator_problems(raw: str, lineno: int) -> list[str]:
    body = raw.strip(" \t")
    seps = re.findall(r"[ \t]+", body)
    bad = [s for s in seps if s != "\t"]
    if bad:
        return [f"line {lineno}: values not separated by single tabs ({bad[0]!r})"]
    return []


def strictness_problems(path: str | Path) -> list[str]:
    """List violations of the writer strictness rules; empty when the file is clean.

    Rules: no trailing tab/space on any line; values on numeric lines (axis value lines and data
    rows) separated by single tabs; every data-block BSDF value has >= 5 significant digits
    unless it is exactly zero; every TIS value has >= 8 significant digits (exact zero is also
    accepted).  A file that :func:`read_bsdf` rejects is reported as a problem too.
    """
    lines = _read_lines(path)
    problems: list[str] = []
    try:
        read_bsdf(path)
    except ValueError as exc:
        problems.append(f"unreadable: {exc}")

    count_kws = {kw.lower() for kw in _COUNT_KEYWORDS}
    expect_values = False
    in_data = False
    for lineno, raw in enumerate(lines, start=1):
        if raw != raw.rstrip(" \t"):
            problems.append(f"line {lineno}: trailing whitespace")
        if _is_comment(raw) or not raw.strip():
            continue
        tokens = raw.split()
        head = tokens[0].lower()
        if expect_values:
            problems += _separator_problems(raw, lineno)
            expect_values = False
            continue
        if head in count_kws:
            expect_values = True
        elif head == "databegin":
            in_data = True
        elif head == "dataend":
            in_data = False
        elif in_data and head == "tis":
            for tok in tokens[1:]:
                if _NUMBER_RE.match(tok) and float(tok) != 0.0 and significant_digits(tok) < 8:
                    problems.append(
                        f"line {lineno}: TIS value {tok!r} has {significant_digits(tok)} "
                        "significant digits (< 8)"
                    )
        elif in_data:
            problems += _separator_problems(raw, lineno)
            for tok in tokens:
                if not _NUMBER_RE.match(tok) or float(tok) == 0.0:
                    continue
                n_sig = significant_digits(tok)
                if n_sig < 5:
                    problems.append(
                        f"line {lineno}: BSDF value {tok!r} has {n_sig} significant digits (< 5)"
                    )
    return problems


# --------------------------------------------------------------------------------------------
# geometry
# --------------------------------------------------------------------------------------------


def _specular_frame_direction(
    aoi_deg: np.ndarray | float, azimuth_deg: np.ndarray | float, radial_deg: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cartesian (x, y, z) of the scattered direction, model frame, broadcast over inputs.

    Specular direction s = (-sin ti, 0, cos ti) (theta = ti, phi = 180 deg).  In-plane axis
    e1 = (cos ti, 0, sin ti) is s rotated by +90 deg about y toward the normal z (azimuth 0);
    at ti = 0 it is +x (phi = 0).  e2 = +y (azimuth 90).  d = cos r s + sin r (cos a e1 +
    sin a e2).
    """
    ti, az, r = np.broadcast_arrays(
        *(np.deg2rad(np.asarray(v, dtype=float)) for v in (aoi_deg, azimuth_deg, radial_deg))
    )
    cos_r, sin_r = np.cos(r), np.sin(r)
    cos_a, sin_a = np.cos(az), np.sin(az)
    cos_t, sin_t = np.cos(ti), np.sin(ti)
    x = -cos_r * sin_t + sin_r * cos_a * cos_t
    y = sin_r * sin_a
    z = cos_r * cos_t + sin_r * cos_a * sin_t
    return x, y, z


def specular_frame_to_model(
    aoi_deg: np.ndarray | float, azimuth_deg: np.ndarray | float, radial_deg: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Map specular-frame (AOI, azimuth, radial) [deg] to model (theta, phi, above).

    theta in [0, 180] deg is the polar angle from the normal, phi in [0, 360) deg the azimuth
    (incident side phi = 0, specular half-plane phi = 180), ``above`` is ``z > 0``.
    """
    x, y, z = _specular_frame_direction(aoi_deg, azimuth_deg, radial_deg)
    theta = np.rad2deg(np.arccos(np.clip(z, -1.0, 1.0)))
    phi = np.mod(np.rad2deg(np.arctan2(y, x)), 360.0)
    phi = np.where(phi >= 360.0, 0.0, phi)[()]
    return theta, phi, z > 0


# --------------------------------------------------------------------------------------------
# integration
# --------------------------------------------------------------------------------------------


def _trapezoid(y: np.ndarray, x: np.ndarray, axis: int = -1) -> np.ndarray:
    """Plain trapezoid rule of ``y`` over the 1-D abscissae ``x`` along ``axis``."""
    y = np.moveaxis(np.asarray(y, dtype=float), axis, -1)
    dx = np.diff(np.asarray(x, dtype=float))
    return np.sum(0.5 * (y[..., 1:] + y[..., :-1]) * dx, axis=-1)


def hemisphere_integral(
    aoi_deg: float,
    azimuth_deg: np.ndarray,
    radial_deg: np.ndarray,
    table: np.ndarray,
    *,
    plane_symmetric: bool | None = None,
) -> float:
    """Integrate BSDF * cos(theta) dOmega over the upper hemisphere for one AOI's table.

    ``table`` is (n_azimuth, n_radial).  dOmega = sin r dr dpsi in the specular frame; cos(theta)
    is the z component of the scattered direction, clipped to 0 below the horizon.  Trapezoid
    in r then psi.  ``plane_symmetric`` defaults to "all azimuths <= 180": then the listed half
    (must span 0..180) is integrated and doubled; otherwise the azimuths are closed periodically
    to 360 deg when needed.
    """
    az = np.asarray(azimuth_deg, dtype=float)
    rad = np.asarray(radial_deg, dtype=float)
    tab = np.asarray(table, dtype=float)
    if tab.shape != (az.size, rad.size):
        raise ValueError(f"table shape {tab.shape} != ({az.size}, {rad.size})")
    if plane_symmetric is None:
        plane_symmetric = bool(az.max() <= 180.0)
    if plane_symmetric:
        if az[0] != 0.0 or az[-1] != 180.0:
            raise ValueError("plane-symmetric table must list azimuths from 0 to 180 deg")
        factor = 2.0
    else:
        factor = 1.0
        if az[-1] - az[0] < 360.0:
            az = np.append(az, az[0] + 360.0)
            tab = np.vstack([tab, tab[:1]])
    _, _, z = _specular_frame_direction(aoi_deg, az[:, None], rad[None, :])
    integrand = tab * np.clip(z, 0.0, None) * np.sin(np.deg2rad(rad))[None, :]
    over_r = _trapezoid(integrand, np.deg2rad(rad), axis=1)
    return float(factor * _trapezoid(over_r, np.deg2rad(az), axis=0))
