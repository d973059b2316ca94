"""Exports to ray tracers: Zemax tabular .BSDF files and TIS-preserving ABg fits, of one
parameter set or of a posterior (median, 95 % bounds and single draws). The .BSDF format
itself, its reader and writer and its specular frame, is :mod:`brdf_infer.tables.bsdf_file`
(re-exported here)."""

from brdf_infer.report.export._abg import AbgFit, fit_abg
from brdf_infer.report.export._files import (
    ABG_COLUMNS,
    export_abg,
    record_export,
    run_export,
)
from brdf_infer.report.export._grid import (
    DEFAULT_AZIMUTH_STEP_DEG,
    DEFAULT_RADIAL_STEP_DEG,
    DEFAULT_THETA_I_DEG,
    ScatterGrid,
    brdf_table,
    scatter_grid,
    table_integral,
)
from brdf_infer.report.export._source import Source, draw_indices, planned_files
from brdf_infer.report.export._zemax import export_zemax
from brdf_infer.runs.folder import EXPORTS_FILE
from brdf_infer.tables.bsdf_file import (
    BsdfFile,
    format_bsdf,
    read_bsdf,
    scattered_direction,
    specular_frame_to_model,
    write_bsdf,
)

__all__ = [
    "ABG_COLUMNS",
    "DEFAULT_AZIMUTH_STEP_DEG",
    "DEFAULT_RADIAL_STEP_DEG",
    "DEFAULT_THETA_I_DEG",
    "EXPORTS_FILE",
    "AbgFit",
    "BsdfFile",
    "ScatterGrid",
    "Source",
    "brdf_table",
    "draw_indices",
    "export_abg",
    "export_zemax",
    "fit_abg",
    "format_bsdf",
    "planned_files",
    "read_bsdf",
    "record_export",
    "run_export",
    "scatter_grid",
    "scattered_direction",
    "specular_frame_to_model",
    "table_integral",
    "write_bsdf",
]
