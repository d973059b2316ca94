"""Generated Zemax tabular .BSDF files, read as a scene's measurements."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from hypothesis import strategies as st

from benchmarks._inputs import _LEVELS, _broken, _number_text, _scene_for_rows
from brdf_infer.tables.measurements import Measurements

_HEADER_VALUES = {
    "Source": ["Measured", "Unknown", "Measured data", ""],
    "Symmetry": ["PlaneSymmetrical", "Asymmetrical", "Asymmetrical4D", "plane"],
    "SpectralContent": ["Monochrome", "Tristimulus", "Spectral"],
    "ScatterType": ["BRDF", "BTDF", "BSDF"],
}


@dataclass(frozen=True)
class BsdfInput:
    """A tabular .BSDF file and the thinning the scene asks for."""

    data: bytes
    keep_every_radial: int
    keep_every_azimuth: int

    def describe(self) -> str:
        return f"thinning {self.keep_every_radial}, {self.keep_every_azimuth}; {self.data[:1500]!r}"


@st.composite
def bsdf_files(draw) -> BsdfInput:
    """A Zemax tabular .BSDF file, well-formed or broken in one or more ways."""
    level = draw(_LEVELS)
    sep = draw(st.sampled_from([" ", "\t", "  ", " \t "]))  # any run of blanks separates
    header = [
        f"{key}{sep}{draw(st.sampled_from(values if _broken(draw, level, 6) else values[:1]))}"
        for key, values in _HEADER_VALUES.items()
    ]
    counts = {
        "SampleRotation": draw(st.integers(1, 2)),
        "AngleOfIncidence": draw(st.integers(1, 3)),
        "ScatterAzimuth": draw(st.integers(1, 4)),
        "ScatterRadial": draw(st.integers(1, 4)),
    }
    ranges = {
        "SampleRotation": (0.0, 360.0),
        "AngleOfIncidence": (0.0, 89.0),
        "ScatterAzimuth": (0.0, 360.0),
        "ScatterRadial": (0.0, 90.0),
    }
    for key, count in counts.items():
        if _broken(draw, level, 6):
            values = [draw(_number_text(-100.0, 400.0)) for _ in range(count)]
        else:
            values = [f"{v:g}" for v in np.linspace(*ranges[key], count, endpoint=False)]
        declared = draw(st.integers(-1, 6)) if _broken(draw, level, 8) else count
        header += [f"{key}{sep}{declared}", sep.join(values)]
    header += [
        draw(st.sampled_from(["Tristimulus", "Spectral"]))
        if _broken(draw, level, 8)
        else "Monochrome",
        "DataBegin",
    ]
    if _broken(draw, level, 6):  # two header lines swapped
        i, j = (draw(st.integers(0, len(header) - 1)) for _ in range(2))
        header[i], header[j] = header[j], header[i]
    body = []
    for _ in range(counts["SampleRotation"]):
        for _ in range(counts["AngleOfIncidence"]):
            body.append(f"TIS{sep}{draw(_number_text(0.0, 1.0, _broken(draw, level, 8)))}")
            for _ in range(counts["ScatterAzimuth"]):
                width = counts["ScatterRadial"] + _broken(draw, level, 10)
                odd = _broken(draw, level, 6)
                body.append(sep.join(draw(_number_text(0.0, 5.0, odd)) for _ in range(width)))
    lines = [f"# generated{sep}file", *header, *body, "DataEnd"]
    if draw(st.integers(0, 5)) == 0:  # blank and comment lines anywhere
        lines.insert(draw(st.integers(0, len(lines))), draw(st.sampled_from(["", "# x", "\t"])))
    newline = draw(st.sampled_from(["\n", "\r\n"]))
    encoding = draw(st.sampled_from(["utf-8", "utf-16", "latin-1"])) if level else "utf-8"
    data = (newline.join(lines) + newline).encode(encoding, errors="replace")
    if _broken(draw, level, 6):  # truncated, or a stray byte
        cut = draw(st.integers(0, len(data)))
        data = draw(st.sampled_from([data[:cut], data[:cut] + b"\xfe" + data[cut:]]))
    return BsdfInput(data, draw(st.integers(1, 3)), draw(st.integers(1, 3)))


def _write_bsdf(folder: Path, given: BsdfInput) -> Path:
    path = folder / "t.BSDF"
    path.write_bytes(given.data)
    return path


def _read_bsdf(path: Path, given: BsdfInput) -> Measurements:
    """Read a generated .BSDF file as a scene's measurements (``export --check`` reads it
    with the same reader)."""
    from brdf_infer.tables.bsdf_measurements import measurements_from_bsdf

    return measurements_from_bsdf(path, given.keep_every_radial, given.keep_every_azimuth)


def _bsdf_command(path: Path, given: BsdfInput) -> list[str]:
    thinning = (
        f"[bsdf]\nkeep_every_radial = {given.keep_every_radial}\n"
        f"keep_every_azimuth = {given.keep_every_azimuth}\n"
    )
    scene = _scene_for_rows(path, path.name, {}, thinning)
    return ["fit", scene, "--method", "paper"]
