"""What a run hands over: the HTML diagnostic report of a posterior run and its figures (imports
matplotlib); the figures and pages of the studies (SBC, comparison, sensitivity), written beside
their results; and, in :mod:`brdf_infer.report.export`, the posterior's BRDF as files for
optical software (Zemax tabular .BSDF, ABg)."""

from brdf_infer.report._build import FIGURE_DIR, REPORT_FILE, write_report
from brdf_infer.report._compare import compare_figure, compare_table_html, write_comparison
from brdf_infer.report._example import write_example
from brdf_infer.report._figures import brdf_bands as plot_brdf_bands
from brdf_infer.report._figures import hemisphere_maps as plot_hemisphere_maps
from brdf_infer.report._figures import posterior_predictive as plot_posterior_predictive
from brdf_infer.report._figures import tis_band as plot_tis_band
from brdf_infer.report._raytrace import figure_png, plot_detector_images, plot_raytrace
from brdf_infer.report._sbc import ecdf_differences, png, sbc_figures, sbc_page, write_sbc
from brdf_infer.report._sensitivity import (
    SENSITIVITY_HEADERS,
    power_scaling_rows,
    sensitivity_figure,
    sensitivity_rows,
    write_sensitivity,
)

__all__ = [
    "FIGURE_DIR",
    "REPORT_FILE",
    "SENSITIVITY_HEADERS",
    "compare_figure",
    "compare_table_html",
    "ecdf_differences",
    "figure_png",
    "plot_brdf_bands",
    "plot_detector_images",
    "plot_hemisphere_maps",
    "plot_posterior_predictive",
    "plot_raytrace",
    "plot_tis_band",
    "png",
    "power_scaling_rows",
    "sbc_figures",
    "sbc_page",
    "sensitivity_figure",
    "sensitivity_rows",
    "write_comparison",
    "write_example",
    "write_report",
    "write_sbc",
    "write_sensitivity",
]
