"""``brdf-infer bench``: run every benchmark on this machine and write one Markdown report."""

from __future__ import annotations

import time
from pathlib import Path

from benchmarks._batch import batch_rows
from benchmarks._cache import cache_rows
from benchmarks._cost_curve import cost_rows, cost_section
from benchmarks._design_section import command_section, design_section
from benchmarks._export import abg_rows, grid_rows
from benchmarks._families import comparison_row, quadrature_rows
from benchmarks._fits import fit_rows
from benchmarks._instrument import bias_rows, ess_rows, node_rows
from benchmarks._misspec import misspec_rows
from benchmarks._model_check_power import (
    QUICK_REPLICATES,
    REPLICATES,
    model_check_power,
    power_section,
)
from benchmarks._raytrace import raytrace_rows
from benchmarks._robustness import loader_rows, robustness_rows
from benchmarks._samplers import sampler_rows
from benchmarks._sbc import sbc_rows
from benchmarks._sections import (
    batch_section,
    cache_section,
    export_section,
    family_section,
    fit_section,
    header_section,
    instrument_section,
    loader_section,
    misspec_section,
    raytrace_section,
    robustness_section,
    sampler_section,
    sbc_section,
    tis_section,
)
from benchmarks._tis import batched_throughput, tis_rows
from brdf_infer._internal.atomic import atomic_write_bytes
from brdf_infer.report import ecdf_differences, figure_png, png
from brdf_infer.scene import load_scene


def _tis_plot(rows, path: Path) -> None:
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(6.4, 4.2))
    for method in dict.fromkeys(row.method for row in rows):
        chosen = [row for row in rows if row.method == method]
        axis.loglog(
            [row.seconds_per_tis * 1e6 for row in chosen],
            [max(row.max_rel_error, 1e-17) for row in chosen],
            marker="o",
            label=method,
        )
    axis.axhline(1e-10, color="grey", linestyle=":", label="1e-10 target")
    axis.set_xlabel("run time per TIS value [µs] (compile excluded)")
    axis.set_ylabel("max relative error of TIS [-]")
    axis.set_title("TIS, Eq. (9): error against run time (uv-paper, θi = 5–70°)")
    axis.legend(fontsize=8)
    figure.tight_layout()
    atomic_write_bytes(path, figure_png(figure, dpi=120))


def _raytrace_plot(rows, path: Path) -> None:
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(6.4, 4.2))
    for configuration in dict.fromkeys(row.configuration for row in rows):
        for estimator, style in (("nee", "o-"), ("naive", "s--")):
            chosen = [
                r for r in rows if r.configuration == configuration and r.estimator == estimator
            ]
            axis.loglog(
                [r.seconds for r in chosen],
                [r.relative_se for r in chosen],
                style,
                label=f"{estimator}, {configuration}",
            )
    axis.axhline(0.01, color="grey", linestyle=":", label="1 % target")
    axis.set_xlabel("run time per configuration [s] (compile excluded)")
    axis.set_ylabel("relative MC standard error of dPs/Pi [-]")
    axis.set_title("Ray tracer (series II, uv-paper): error against run time")
    axis.legend(fontsize=7)
    figure.tight_layout()
    atomic_write_bytes(path, figure_png(figure, dpi=120))


def write_report(out: Path, quick: bool, progress=print) -> Path:
    """Run the benchmarks and write ``out`` (Markdown) plus PNG plots beside it."""
    started = time.perf_counter()
    progress("benchmark 1/12: TIS quadratures ...")
    tis_table = tis_rows(quick)
    count, batch_seconds, batch_compile = batched_throughput(quick)
    progress("benchmark 2/12: fits ...")
    scene = load_scene("lya")
    fits = fit_rows(scene, scene.load_measurements(), quick)
    progress("benchmark 3/12: samplers ...")
    samplers, reference = sampler_rows(scene, quick, progress)
    progress("benchmark 4/12: ray tracer ...")
    traces, reference_rays = raytrace_rows(scene, quick)
    progress("benchmark 5/12: sampling robustness ...")
    robustness = robustness_rows(scene, quick, progress)
    loaders = loader_rows(500 if quick else 5000, progress)
    progress("benchmark 6/12: simulation-based calibration ...")
    calibrations = sbc_rows(scene, quick, progress)
    progress("benchmark 7/12: misspecification ...")
    misspecified = misspec_rows(scene, quick, progress)
    progress("benchmark: the model checks' power ...")
    power = model_check_power(QUICK_REPLICATES if quick else REPLICATES, progress=progress)
    progress("benchmark: experimental design (estimate against refit, pay-off) ...")
    design_lines = design_section(quick, out.with_name(out.stem + "_design.png"), progress)
    design_lines += command_section(quick, progress)
    progress("benchmark: cost against the number of rows ...")
    cost_lines = cost_section(cost_rows(quick, progress), quick)
    progress("benchmark 8/12: exports ...")
    grids, abgs = grid_rows(quick), abg_rows(quick)
    progress("benchmark 9/12: model families ...")
    quadratures = quadrature_rows(quick)
    comparison = comparison_row(scene, scene.load_measurements(), quick)
    progress("benchmark 10/12: batch inference ...")
    batches = batch_rows(scene, quick, progress=progress)
    progress("benchmark 11/12: compilation cache ...")
    caches = cache_rows(quick, progress)
    progress("benchmark 12/12: instrument kernels ...")
    measurements = scene.load_measurements()
    kernel_nodes = node_rows(scene, measurements, quick, progress)
    kernel_ess = ess_rows(scene, measurements, quick, progress)
    biases, _ = bias_rows(scene, measurements, quick, progress)
    sbc_plots = []
    for row, suffix in zip(calibrations[:2], ("sbc", "sbc_planted"), strict=True):
        path = out.with_name(f"{out.stem}_{suffix}.png")
        atomic_write_bytes(path, png(ecdf_differences(row.result)))
        sbc_plots.append(path)
    plot = out.with_name(out.stem + "_tis.png")
    _tis_plot(tis_table, plot)
    trace_plot = out.with_name(out.stem + "_raytrace.png")
    _raytrace_plot(traces, trace_plot)

    sections = [
        *header_section(quick, started),
        *tis_section(tis_table, plot, count, batch_seconds, batch_compile),
        *fit_section(fits),
        *sampler_section(samplers, reference),
        *raytrace_section(traces, reference_rays, trace_plot),
        *robustness_section(robustness),
        *loader_section(loaders),
        *sbc_section(calibrations, sbc_plots),
        *misspec_section(misspecified),
        *power_section(power),
        *export_section(grids, abgs),
        *family_section(quadratures, comparison, quick),
        *batch_section(batches),
        *cache_section(caches),
        *instrument_section(kernel_nodes, kernel_ess, biases),
        *design_lines,
        *cost_lines,
    ]
    atomic_write_bytes(out, "\n".join(sections).encode())
    return out
