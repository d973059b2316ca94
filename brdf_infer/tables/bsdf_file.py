"""Zemax / Radiant "BSDF Data Interchange" tabular files (.BSDF): their reader and writer, and
their specular frame. Read as measurements (:mod:`brdf_infer.tables.bsdf_measurements`) and written
as exports (:mod:`brdf_infer.report.export`).

Layout (one keyword per line; ``#`` starts a comment line)::

    Source Measured
    Symmetry PlaneSymmetrical
    SpectralContent Monochrome
    ScatterType BRDF
    SampleRotation 1
    0
    AngleOfIncidence N
    <N angles>
    ScatterAzimuth N
    <N azimuths>
    ScatterRadial N
    <N radials>

    Monochrome
    DataBegin
    TIS <value>                 (for every sample rotation, every angle of incidence)
    <one row per azimuth: one BSDF value [sr⁻¹] per radial>
    DataEnd

Values are tab-separated with no trailing whitespace (strict readers refuse anything else);
BSDF values carry 7 significant digits, TIS values 11. Angles in degrees; the scatter
angles are in the specular frame (below).

Frame of the BSDF Data Interchange format: the radial angle r is the angle between the
scattered and the specular direction (r = 0 is specular), the azimuth ψ turns about the
specular direction with ψ = 0 pointing from the specular direction toward the surface
normal. The model's frame (Eq. 8): z is the normal, the forward-scattering half-plane is
φ = 180°, so the specular ray of incidence θi is s = (−sin θi, 0, cos θi). With
u = (cos θi, 0, sin θi) (unit, ⟂ s, toward the normal; at θi = 0 its limit, the backward
direction) and v = (0, 1, 0):

    d(ψ, r) = cos r · s + sin r · (cos ψ · u + sin ψ · v).

ψ = 0, r = θi is the normal; ψ = 180°, r = 90° − θi the forward horizon; ψ = 0,
r = 90° + θi the backward horizon. The model is symmetric about the plane of incidence, so
ψ ∈ [0°, 180°] describes the whole hemisphere (``PlaneSymmetrical``).

``Source``: the format's specification (Radiant Imaging / Zemax, "BSDF Data Interchange File
Format Specification") defines one value, ``Measured``; no value for model-derived tables
exists, so the writer keeps ``Measured`` (a reader that checks the keyword accepts the file)
and the exporter says in a comment line that its tables are a model on a grid. The reader
keeps whatever a file says.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from brdf_infer._internal.atomic import atomic_write_bytes
from brdf_infer.errors import BadInputError

_BSDF_FORMAT = "{:.6e}"  # 7 significant digits
_TIS_FORMAT = "{:.10e}"  # 11 significant digits
_SYMMETRIES = ("PlaneSymmetrical", "Asymmetrical")
BSDF_SOURCE = "Measured"  # the only Source value the format defines (module docstring)


@dataclass
class BsdfFile:
    """Contents of a tabular BSDF file.

    Attributes:
        theta_i_deg: angles of incidence [deg], shape (n_aoi,).
        azimuth_deg: scatter azimuths [deg], shape (n_azimuth,).
        radial_deg: scatter radials [deg], shape (n_radial,).
        tis: TIS line of every block, shape (n_rotation, n_aoi).
        bsdf: tables [sr⁻¹], shape (n_rotation, n_aoi, n_azimuth, n_radial).
        symmetry: ``PlaneSymmetrical`` or ``Asymmetrical``.
        scatter_type: ``BRDF`` or ``BTDF``.
        source: the ``Source`` keyword (:data:`BSDF_SOURCE` when written; as read otherwise).
        sample_rotation_deg: sample rotations [deg], shape (n_rotation,).
        comments: comment lines without their ``#``.
    """

    theta_i_deg: np.ndarray
    azimuth_deg: np.ndarray
    radial_deg: np.ndarray
    tis: np.ndarray
    bsdf: np.ndarray
    symmetry: str = "PlaneSymmetrical"
    scatter_type: str = "BRDF"
    source: str = BSDF_SOURCE
    sample_rotation_deg: np.ndarray = field(default_factory=lambda: np.zeros(1))
    comments: list[str] = field(default_factory=list)


# ---------------------------------------------------------------------------- frame


def scattered_direction(theta_i_deg, azimuth_deg, radial_deg):
    """Unit vector d(ψ, r) of the specular frame in the model's frame (module docstring).

    Returns:
        (x, y, z) arrays broadcast over the three arguments.
    """
    theta_i = jnp.radians(jnp.asarray(theta_i_deg, float))
    psi = jnp.radians(jnp.asarray(azimuth_deg, float))
    r = jnp.radians(jnp.asarray(radial_deg, float))
    sin_i, cos_i = jnp.sin(theta_i), jnp.cos(theta_i)
    x = jnp.cos(r) * -sin_i + jnp.sin(r) * jnp.cos(psi) * cos_i
    y = jnp.sin(r) * jnp.sin(psi)
    z = jnp.cos(r) * cos_i + jnp.sin(r) * jnp.cos(psi) * sin_i
    return x, y, z


def specular_frame_to_model(theta_i_deg, azimuth_deg, radial_deg):
    """(θ, φ) [deg] of the model (Eq. 8) for a specular-frame direction, and z = cos θ.

    θ is clipped to 90° below the horizon (where z < 0 and the BSDF is 0).
    """
    x, y, z = scattered_direction(theta_i_deg, azimuth_deg, radial_deg)
    theta = jnp.degrees(jnp.arccos(jnp.clip(z, 0.0, 1.0)))
    phi = jnp.mod(jnp.degrees(jnp.arctan2(y, x)), 360.0)
    return theta, phi, z


# ---------------------------------------------------------------------------- writer


def _angles(values: np.ndarray) -> str:
    return "\t".join(f"{float(v):g}" for v in values)


def format_bsdf(contents: BsdfFile) -> str:
    """The file's text (see the module docstring)."""
    tis = np.asarray(contents.tis, float).reshape(len(contents.sample_rotation_deg), -1)
    bsdf = np.asarray(contents.bsdf, float)
    lines = [f"# {comment}".rstrip() for comment in contents.comments]
    lines += [
        f"Source {contents.source}",
        f"Symmetry {contents.symmetry}",
        "SpectralContent Monochrome",
        f"ScatterType {contents.scatter_type}",
        f"SampleRotation {len(contents.sample_rotation_deg)}",
        _angles(contents.sample_rotation_deg),
        f"AngleOfIncidence {len(contents.theta_i_deg)}",
        _angles(contents.theta_i_deg),
        f"ScatterAzimuth {len(contents.azimuth_deg)}",
        _angles(contents.azimuth_deg),
        f"ScatterRadial {len(contents.radial_deg)}",
        _angles(contents.radial_deg),
        "",
        "Monochrome",
        "DataBegin",
    ]
    for rotation in range(tis.shape[0]):
        for aoi in range(tis.shape[1]):
            lines.append("TIS " + _TIS_FORMAT.format(tis[rotation, aoi]))
            table = np.where(bsdf[rotation, aoi] > 0.0, bsdf[rotation, aoi], 0.0)
            lines += ("\t".join(_BSDF_FORMAT.format(v) for v in row) for row in table)
    lines.append("DataEnd")
    return "\n".join(lines) + "\n"


def write_bsdf(path: str | Path, contents: BsdfFile) -> Path:
    """Write ``contents`` atomically to ``path``."""
    return atomic_write_bytes(path, format_bsdf(contents).encode("ascii"))


# ---------------------------------------------------------------------------- reader


class _Lines:
    """Non-comment, non-blank lines with their 1-based numbers, and the comments."""

    def __init__(self, path: Path, text: str):
        self.path = path
        self.comments: list[str] = []
        self._items: list[tuple[int, str]] = []
        lines = text.splitlines()
        for number, line in enumerate(lines, start=1):
            stripped = line.strip()
            if stripped.startswith("#"):
                self.comments.append(stripped[1:].strip())
            elif stripped:
                self._items.append((number, stripped))
        self._position = 0
        self.last_line = len(lines)

    def error(self, problem: str, line: int | None = None) -> BadInputError:
        return BadInputError(problem, file=self.path, line=line)

    def next(self, expecting: str) -> tuple[int, str]:
        if self._position >= len(self._items):
            raise self.error(f"file ends where {expecting} was expected", self.last_line)
        item = self._items[self._position]
        self._position += 1
        return item

    def remaining(self) -> Iterator[tuple[int, str]]:
        while self._position < len(self._items):
            yield self.next("")


def _numbers(lines: _Lines, number: int, text: str, count: int, what: str) -> np.ndarray:
    words = text.split()
    if len(words) != count:
        raise lines.error(f"{what}: expected {count} values, found {len(words)}", number)
    try:
        values = np.array([float(w) for w in words])
    except ValueError:
        bad = next(w for w in words if not _is_number(w))
        raise lines.error(f"{what}: '{bad}' is not a number", number) from None
    if not np.all(np.isfinite(values)):
        raise lines.error(f"{what}: values must be finite", number)
    return values


def _is_number(word: str) -> bool:
    try:
        float(word)
    except ValueError:
        return False
    return True


def _split(text: str) -> tuple[str, str]:
    """(keyword, the rest) of a line; any run of blanks (spaces, tabs) separates them."""
    words = text.split(None, 1)
    return (words[0], words[1].strip()) if len(words) == 2 else (text, "")


_KEYWORDS = ("Source", "Symmetry", "SpectralContent", "ScatterType")
_COUNTED = ("SampleRotation", "AngleOfIncidence", "ScatterAzimuth", "ScatterRadial")


def _counted_angles(lines: _Lines, keyword: str, number: int, value: str) -> np.ndarray:
    try:
        count = int(value)
    except ValueError:
        raise lines.error(f"'{keyword}' needs a count, found '{value[:40]}'", number) from None
    if count < 1:
        raise lines.error(f"'{keyword}' needs a positive count, found {count}", number)
    number, text = lines.next(f"the {count} values of '{keyword}'")
    return _numbers(lines, number, text, count, keyword)


def _header(lines: _Lines) -> tuple[dict[str, tuple[int, str]], dict[str, np.ndarray]]:
    """The header up to ``DataBegin``, its lines in any order: (keyword → (line, value),
    counted keyword → its values)."""
    keywords: dict[str, tuple[int, str]] = {}
    counted: dict[str, np.ndarray] = {}
    spectral = None
    while True:
        number, text = lines.next("'DataBegin'")
        if text == "DataBegin":
            break
        name, value = _split(text)
        if name in keywords or name in counted:
            raise lines.error(f"'{name}' appears twice", number)
        if name in _KEYWORDS:
            keywords[name] = (number, value)
        elif name in _COUNTED:
            counted[name] = _counted_angles(lines, name, number, value)
        elif spectral is None and not value and name in ("Monochrome", "Tristimulus"):
            spectral = (number, name)
        else:
            raise lines.error(f"unexpected '{text[:40]}' in the header", number)
    missing = [name for name in (*_KEYWORDS, *_COUNTED) if name not in keywords | counted]
    if missing:
        raise lines.error(f"the header lacks '{missing[0]}' before 'DataBegin'", number)
    if spectral is None:
        raise lines.error("expected 'Monochrome' before 'DataBegin'", number)
    if spectral[1] != "Monochrome":
        raise lines.error(f"'{spectral[1]}' data are not supported (Monochrome)", spectral[0])
    return keywords, counted


def read_bsdf(path: str | Path) -> BsdfFile:
    """Read a tabular BSDF file (plane-symmetric or asymmetric, monochrome).

    The header's lines may come in any order, and any run of spaces and tabs separates words.

    Raises:
        BadInputError: the file is missing, unreadable or malformed; the message names the
            file and line.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8", errors="strict")
    except FileNotFoundError:
        raise BadInputError("no such file", file=path) from None
    except (OSError, UnicodeDecodeError) as error:
        raise BadInputError(f"cannot read: {error}", file=path) from None
    lines = _Lines(path, text)
    keywords, counted = _header(lines)
    source = keywords["Source"][1]
    number, symmetry = keywords["Symmetry"]
    if symmetry not in _SYMMETRIES:
        raise lines.error(f"Symmetry must be one of {', '.join(_SYMMETRIES)}", number)
    number, spectral = keywords["SpectralContent"]
    if spectral != "Monochrome":
        raise lines.error(
            f"SpectralContent '{spectral[:40]}' is not supported (Monochrome)", number
        )
    number, scatter_type = keywords["ScatterType"]
    if scatter_type not in ("BRDF", "BTDF"):
        raise lines.error(f"ScatterType must be BRDF or BTDF, found '{scatter_type[:40]}'", number)
    rotation, theta_i, azimuth, radial = (counted[name] for name in _COUNTED)
    tis = np.empty((rotation.size, theta_i.size))
    bsdf = np.empty((rotation.size, theta_i.size, azimuth.size, radial.size))
    for r in range(rotation.size):
        for a in range(theta_i.size):
            number, text = lines.next(f"'TIS' of angle of incidence {theta_i[a]:g}")
            name, value = _split(text)
            if name != "TIS":
                raise lines.error(f"expected 'TIS <value>', found '{text[:40]}'", number)
            tis[r, a] = _numbers(lines, number, value, 1, "TIS")[0]
            for k in range(azimuth.size):
                number, text = lines.next(f"the row of azimuth {azimuth[k]:g}")
                bsdf[r, a, k] = _numbers(lines, number, text, radial.size, "BSDF row")
    number, text = lines.next("'DataEnd'")
    if text != "DataEnd":
        raise lines.error(f"expected 'DataEnd', found '{text[:40]}'", number)
    for number, text in lines.remaining():
        raise lines.error(f"unexpected content after DataEnd: '{text[:40]}'", number)
    if np.any(bsdf < 0.0) or np.any(tis < 0.0):
        raise BadInputError("negative BSDF or TIS values", file=path)
    return BsdfFile(
        theta_i_deg=theta_i,
        azimuth_deg=azimuth,
        radial_deg=radial,
        tis=tis,
        bsdf=bsdf,
        symmetry=symmetry,
        scatter_type=scatter_type,
        source=source,
        sample_rotation_deg=rotation,
        comments=lines.comments,
    )
