"""A small synthetic vendor .BSDF table for the table-view tests: ``uv-paper``'s BRDF (folded
by Eq. 10, as a scatterometer measures it) at a few angles of incidence, with 5 % log-normal
noise, a few zero cells in the far tails and, when asked, one planted dropout."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from brdf_infer.model import brdf_hemisphere
from brdf_infer.model.params import UV_PAPER
from brdf_infer.tables.bsdf_file import BsdfFile, specular_frame_to_model, write_bsdf

AOI_DEG = (10.0, 30.0, 50.0, 70.0)
AZIMUTH_DEG = np.arange(0.0, 181.0, 30.0)  # 0 and 180: the plane of incidence
RADIAL_DEG = np.arange(0.0, 91.0, 7.5)
ZERO_CELLS = ((0, 1, 12), (1, 2, 11), (2, 3, 7))  # (AOI, azimuth, radial) indices set to 0
DROPOUT_CELL = (1, 3, 4)  # θi 30°, ψ 90° (out of the plane), r 30°
DROPOUT_FACTOR = 10.0  # 3.6e-3 among neighbours of 3.6e-2


def vendor_table(dropout: bool = True, seed: int = 3) -> BsdfFile:
    """The table (module docstring); zero cells are above the horizon, the dropout a tenth of
    its noisy value."""
    grid_azimuth, grid_radial = np.meshgrid(AZIMUTH_DEG, RADIAL_DEG, indexing="ij")
    noise = np.random.default_rng(seed)
    tables = []
    for theta_i in AOI_DEG:
        theta, phi, z = (
            np.asarray(a) for a in specular_frame_to_model(theta_i, grid_azimuth, grid_radial)
        )
        values = np.asarray(brdf_hemisphere(theta_i, theta, phi, UV_PAPER, True))
        values = values * np.exp(noise.normal(0.0, 0.05, values.shape))
        tables.append(np.where((z > 0.0) & (theta < 90.0), values, 0.0))
    bsdf = np.array(tables)
    for cell in ZERO_CELLS:
        bsdf[cell] = 0.0
    if dropout:
        bsdf[DROPOUT_CELL] /= DROPOUT_FACTOR
    return BsdfFile(
        np.asarray(AOI_DEG), AZIMUTH_DEG, RADIAL_DEG, np.full((1, len(AOI_DEG)), 0.05), bsdf[None]
    )


def write_vendor_scene(folder: Path, dropout: bool = True, extra: str = "") -> Path:
    """``vendor.bsdf`` and a scene ``vendor.toml`` reading it (σ 5 %, folded like the table)."""
    write_bsdf(folder / "vendor.bsdf", vendor_table(dropout))
    scene = folder / "vendor.toml"
    scene.write_text(
        'name = "vendor"\nmeasurements = "vendor.bsdf"\n[model]\nfold = true\n'
        "[errors]\nreflectance_rel = 0.05\n" + extra
    )
    return scene
