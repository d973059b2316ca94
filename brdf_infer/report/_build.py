"""``brdf-infer report RUN_DIR``: diagnostics first, then fit against data, then products."""

from __future__ import annotations

import gc
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from brdf_infer._internal import arviz as az
from brdf_infer._internal.outlock import require_complete, writing
from brdf_infer._internal.precision import ensure_float64
from brdf_infer.errors import BadInputError
from brdf_infer.model import fold_statement
from brdf_infer.posterior import (
    THRESHOLDS,
    draws_params,
    family_draws,
    run_measurements,
    run_scene,
)
from brdf_infer.report import _chains, _figures, _html, _noise
from brdf_infer.report._compare import compare_section
from brdf_infer.report._design import design_section
from brdf_infer.report._error_model import (
    error_model_table,
    loo_pits,
    loo_table,
    variants_comparison,
)
from brdf_infer.report._export import export_section, load_exports, plot_export
from brdf_infer.report._instruments import instruments_section
from brdf_infer.report._raytrace import plot_detector_images, plot_raytrace
from brdf_infer.report._results import fold_note, result_box, tis_fold, tis_table
from brdf_infer.report._run_tables import run_section, summary_table
from brdf_infer.report._saver import FigureSaver
from brdf_infer.report._sensitivity import sensitivity_section
from brdf_infer.report._table_views import residual_hemisphere, value_words
from brdf_infer.report._traces import raytrace_table
from brdf_infer.runs.folder import (
    FIGURE_DIR,
    POSTERIOR_FILE,
    REPORT_FILE,
    SUMMARY_FILE,
    RunFolder,
)
from brdf_infer.scene import tis_angles
from brdf_infer.studies.raytrace import load_detector_images
from brdf_infer.verdict import PARETO_K_LIMIT, Verdict, limit_text

__all__ = ["FIGURE_DIR", "REPORT_FILE", "write_report"]


def _load(run: RunFolder):
    """The run's posterior, summary and bands.

    Raises:
        BadInputError: one of them absent or unreadable, or a summary without a verdict.
    """
    if not run.posterior_file.is_file():
        raise BadInputError(
            f"no {POSTERIOR_FILE} here (run 'brdf-infer posterior --out DIR' first)",
            file=run.path,
        )
    summary, bands = run.summary(), run.bands()
    try:
        idata = az.from_netcdf(run.posterior_file)
    except (OSError, ValueError) as error:
        raise BadInputError(f"cannot read the run: {error}", file=run.posterior_file) from None
    if "verdict" not in summary:
        raise BadInputError(
            "no verdict in this run's summary (written by an earlier brdf_infer): run it again",
            file=run.file(SUMMARY_FILE),
        )
    return idata, summary, bands


def write_report(run: Path, progress=print) -> tuple[Path, Verdict]:
    """Write ``run/report.html`` and ``run/figures/*.png``; returns the path and the run's
    verdict (the one the run recorded, rendered as it stands).

    Raises:
        BadInputError: ``run`` is no complete run folder (:mod:`brdf_infer._internal.outlock`: one
            being written, or left incomplete by a writer that stopped), or another process
            writes its report.
    """
    started = time.perf_counter()
    ensure_float64()  # the rows are predicted again: float32 would not carry the model
    require_complete(run)
    folder = RunFolder(run)
    with _collection_deferred(), FigureSaver(progress) as saver:  # it starts while we read
        loaded = _load(folder)
        with writing(run, "report", option="RUN_DIR", adds=True):
            return _write_report(folder, loaded, saver, started, progress)


@contextmanager
def _collection_deferred() -> Iterator[None]:
    """No cyclic garbage collection inside: reading the run and drawing every figure leave
    objects in reference cycles, and each full collection scans all of the process's objects
    (≈ 3·10⁵ with JAX and the run loaded, ≈ 0.2 s); the cycles (≈ 40 MB for the bundled scene)
    are left to the first collection after the report. Enabled again on the way out, if it
    was."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


AddFigure = Callable[[str, str, Callable[[], object]], None]  # name, caption, make the figure


@dataclass
class Figures:
    """The report's figures in the order drawn: their captions by name, their PNGs saved by
    ``saver`` (while the tables are written)."""

    saver: FigureSaver
    captions: dict[str, str] = field(default_factory=dict)

    def shown(self, *names: str) -> list[str]:
        """The HTML of the figures named, in the order they were drawn."""
        return [
            _html.figure(self.saver.png(name), caption)
            for name, caption in self.captions.items()
            if name in names
        ]


def _write_report(
    run: RunFolder, loaded, saver: FigureSaver, started: float, progress
) -> tuple[Path, Verdict]:
    idata, summary, bands = loaded
    attrs = idata.posterior.attrs
    scene = run_scene(attrs)  # what the run sampled, not the scene file as it is now
    member, physical = family_draws(idata.posterior)
    rows = run_measurements(idata)  # the rows it sampled, kept in the run
    rows = scene.load_measurements() if rows is None else rows  # a run from before they were
    loo = summary["predictive"]  # PSIS-LOO as the run computed it
    verdict = Verdict.from_json(summary["verdict"])  # recorded when the run completed
    figures = Figures(saver)

    def add(name: str, caption: str, make) -> None:
        progress(f"  figure: {name}")
        figures.captions[name] = caption
        saver.save(name, make())

    with ThreadPoolExecutor(1) as background:  # the maps' values while other figures are drawn
        maps = (
            background.submit(_figures.hemisphere_values, member, physical)
            if scene.outputs.maps and member.hemispheric(scene.model.out_of_plane)
            else None
        )
        _fit_figures(add, run, idata, summary, bands, scene, rows, loo)
        _product_figures(add, bands, scene, member, physical, maps)
    exports = load_exports(run)
    _export_figure(add, exports, idata, scene, member.paper_parameters)
    traces = run.traces()
    _raytrace_figures(add, traces, load_detector_images(run.path))

    sections = [
        *_answer(run, verdict, summary, bands, scene, rows, member, figures),
        *run_section(scene, rows, idata, summary, member),
        "<h2>ArviZ summary (physical units)</h2>",
        summary_table(idata, summary, member),
        *_diagnostics(run, idata, summary, loo, figures),
        *_products(run, bands, exports, traces, figures),
    ]
    for name in figures.captions:
        run.write_bytes(f"{FIGURE_DIR}/{name}.png", saver.png(name))
    title = f"brdf_infer report: {scene.name}, {member.name} ({attrs['sampler']})"
    document = _html.page(title, sections)
    path = run.write_bytes(REPORT_FILE, document.encode())
    progress(f"report written in {time.perf_counter() - started:.1f} s")
    return path, verdict


def _fit_figures(add: AddFigure, run: RunFolder, idata, summary, bands, scene, rows, loo) -> None:
    """The BRDF bands against the data, the sampler's diagnostics and the fit to the data."""
    reference = scene.outputs.reference_params
    out_of_plane = int(rows.out_of_plane.sum())
    add(
        "brdf_bands",
        "In-plane BRDF at the scene's incidence angles, each of them: posterior median, 68 % "
        "and 95 % bands, and the measured rows in the plane of incidence (φs 0° or 180°)"
        + (
            " as BRDF values"
            if rows.quantity == "brdf"
            else ", raw reflectance converted by Eq. (6)"
        )
        + (
            f"; the {out_of_plane} out-of-plane rows are in the residual map"
            if out_of_plane
            else ""
        )
        + (f"; dashed: the reference parameter set '{reference}'" if reference else "")
        + ".",
        lambda: _figures.brdf_bands(bands, scene, rows),
    )
    if summary["sampler"] != "laplace":  # resampled importance draws: no chain to follow
        add(
            "trace",
            "Trace plots in the sampler's well-conditioned coordinates (ln BRDF0, b1–b3, α, "
            "θs0 and the sampled noise scales).",
            lambda: _chains.trace(idata),
        )
        add(
            "rank",
            "Rank plots: chains that mix give flat histograms.",
            lambda: _chains.rank(idata),
        )
    add("pair", "Pair plot; divergent transitions marked.", lambda: _chains.pair(idata))
    if "energy" in idata.sample_stats:
        add("energy", "NUTS energy plot.", lambda: _chains.energy(idata))
    add(
        "predictive",
        f"Posterior predictive against the measured {value_words(rows.quantity)} of the rows in "
        "the plane of incidence, per series (cf. Figs. 4, 6)"
        + (
            f"; the {out_of_plane} out-of-plane rows are in the residual map."
            if out_of_plane
            else "."
        ),
        lambda: _figures.posterior_predictive(idata, rows),
    )
    if out_of_plane or summary.get("table"):
        add(
            "residual_map",
            "Every row's residual on the hemisphere, one panel per incidence angle: ln value − "
            "the median of its posterior-predictive replicates (red: the data lie above the "
            "model); the table's zero cells and dropouts, left out by the rules of the Data "
            "section, are marked where they lie.",
            lambda: residual_hemisphere(idata, rows, summary.get("table")),
        )
    pits = loo_pits(run, summary)
    if pits:
        add(
            "loo_pit",
            "LOO-PIT of the leave-one-out predictive of each row under this run's error model and "
            "under the earlier spread model (σ² = 6.5 %² + s(θi)²), where the run has it as a "
            "variant; Kolmogorov–Smirnov p-values of uniformity in the titles.",
            lambda: _noise.loo_pit_comparison(pits),
        )
    spread = _noise.spread_check(idata)
    if spread is not None:
        add(
            "spread_check",
            "Inter-sample spread per θi: the sd of ln R over the samples measured at one "
            "geometry (points) against its posterior predictive distribution (bars) and the "
            "fitted sample-to-sample scale τ (green).",
            lambda: spread,
        )
    if "pareto_k" in loo:  # runs written before it was recorded: no figure
        add("pareto_k", "PSIS-LOO Pareto k per measurement.", lambda: _figures.pareto_k(loo))


def _product_figures(
    add: AddFigure, bands, scene, member, physical, maps: Future[_figures.HemisphereMaps] | None
) -> None:
    """The TIS band and the hemisphere maps (their values computed in ``maps``), where the run
    has them."""
    if "tis" in bands:
        add(
            "tis_band",
            "TIS(θi): posterior median, 68 % and 95 % bands"
            + (", with the scene's reference points" if scene.outputs.tis_reference else "")
            + f"; {fold_statement(tis_fold(bands))}.",
            lambda: _figures.tis_band(bands, scene.load_tis_reference()),
        )
    if maps is not None:
        add(
            "hemisphere",
            "Hemisphere maps (cf. Fig. 9): posterior median BRDF on one logarithmic colour scale "
            "(top) and the relative width of its 95 % band (bottom); "
            f"{fold_statement(member.fold)}.",
            lambda: _figures.hemisphere_maps(member, physical, maps=maps.result()),
        )


def _export_figure(add: AddFigure, exports: list[dict], idata, scene, eq7: bool) -> None:
    """The last .BSDF export of the run read back, against the model (``eq7``: a run of
    Eq. (7)'s family; the figure evaluates Eq. 7 directly)."""
    shown = next((e for e in reversed(exports) if e["format"] == "zemax-bsdf"), None)
    if shown is not None and eq7:
        tables = {f["kind"]: Path(f["path"]) for f in shown["files"] if f["kind"] != "draw"}
        fold = shown.get("fold", True)  # exports before the "fold" key folded by default
        add(
            "export",
            "Exported .BSDF tables read back as a ray tracer reads them, cut through the plane "
            "of incidence (black: median solid, 95 % bounds dotted), against the model's "
            f"posterior median and 95 % band evaluated directly (blue); {fold_statement(fold)}.",
            lambda: plot_export(tables, draws_params(idata.posterior), fold, scene.model.constants),
        )


def _raytrace_figures(add: AddFigure, traces: list[dict], images: dict | None) -> None:
    """The ray traces against the measurements (Fig. 14) and the detector images (Fig. 13),
    as the run wrote them."""
    if traces:
        add(
            "raytrace",
            "Ray-traced raw reflectance of the series II setup against the measurements "
            "(cf. Fig. 14): dPs/Pi through the detector aperture (crosses; shaded: 95 % band "
            "over posterior draws), the Eq. (6) point estimate (dotted) and the paper's image "
            "ratio over the signal square (small squares).",
            lambda: plot_raytrace(traces),
        )
    if traces and images is not None:
        add(
            "detector_images",
            f"Simulated detector images for {traces[0]['params_source']} (cf. Fig. 13); the "
            "cyan square is the signal region of the image ratio.",
            lambda: plot_detector_images(images),
        )


def _thresholds(summary) -> str:
    """The thresholds the run's verdict applied, in words (the leave-one-out terms' k̂ limit
    that of the draws PSIS-LOO read: ``pareto_k_limit``)."""
    loo = limit_text(summary["predictive"].get("pareto_k_limit", PARETO_K_LIMIT))
    if summary["sampler"] == "laplace":
        return (
            f"Laplace + PSIS: the importance weights' Pareto k within the limit of their "
            f"number (≤ {PARETO_K_LIMIT}) and their effective sample size ≥ "
            f"{THRESHOLDS['ess']} (R-hat between its chains, slices of one weighted set, is "
            f"recorded, not checked); Pareto k ≤ {loo} for every row's leave-one-out term."
        )
    return (
        f"R-hat ≤ {THRESHOLDS['r_hat']}, bulk and tail ESS ≥ {THRESHOLDS['ess']}, "
        f"no divergences, BFMI ≥ {THRESHOLDS['bfmi']}, Pareto k ≤ {loo}, "
        f"emcee ≥ {THRESHOLDS['tau_multiple']} autocorrelation times."
    )


def _answer(
    run: RunFolder, verdict, summary, bands, scene, rows, member, figures: Figures
) -> list[str]:
    """The verdict and the answer first, with the BRDF bands and the studies left out."""
    return [
        _html.verdict_box(verdict),
        "<p>Thresholds: " + _html.escape(_thresholds(summary)) + "</p>",
        model_check_table(summary.get("model_check")),
        result_box(summary, bands, tis_angles(scene, rows), member),
        fold_note(bands, scene.outputs.reference_params is not None) if "tis" in bands else "",
        *figures.shown("brdf_bands"),
        _studies_line(run),
    ]


CHECK_WORDS = {
    "fit_repeatability": "least squares: scatter beyond the rows' σ",
    "fit_chi2": "least squares: χ² against the rows' σ",
    "fit_residual_trend": "least squares: residual trends",
    "loo_pit": "posterior: LOO-PIT uniformity",
    "residual_trend": "posterior: leave-one-out residual trends",
    "at_bound": "posterior: a parameter at a bound",
}


def model_check_table(record: dict | None) -> str:
    """The model check, every check with its statistic, p-value, finding and what it could
    detect (80 % power at p < 0.001): a passed check has shown no misfit of that size, not
    that there is none. Nothing for a run written before the record."""
    if record is None:
        return ""
    rows = [
        [
            CHECK_WORDS.get(entry["name"], entry["name"]),
            "passed" if entry["ok"] else "FAILED",
            "-" if entry["statistic"] is None else f"{entry['statistic']:.3g}",
            "-" if entry["p"] is None else f"{entry['p']:.2g}",
            entry["words"],
            entry["detectable"],
        ]
        for entry in record["checks"]
    ]
    head = (
        "The model against the data: every check passed."
        if record["ok"]
        else "The model against the data: the data reject the model; every band below is "
        "conditional on it. Next: " + "; or ".join(record.get("next", []))
    )
    return (
        "<h2>Model check</h2><p>"
        + _html.escape(head)
        + "</p>"
        + _html.table(
            ["check", "result", "statistic", "p", "found", "could detect (80 % power)"], rows
        )
    )


def _sampler_line(summary) -> str:
    """A Laplace run's importance weights, or why Laplace was refused (else nothing)."""
    diagnostics = summary["diagnostics"]
    if "laplace_refused" in diagnostics:
        return (
            "<p>"
            + _html.escape(
                f"Laplace + PSIS refused: {diagnostics['laplace_refused']}; sampled with NUTS."
            )
            + "</p>"
        )
    importance = diagnostics.get("importance")
    if importance is None:
        return ""
    return (
        "<p>"
        + _html.escape(
            f"Laplace + PSIS: {importance['proposals']} proposals after "
            f"{importance['adaptations']} adaptation(s) of the Student-t proposal; the importance "
            f"weights' Pareto k {importance['pareto_k']:.2f}, effective sample size "
            f"{importance['ess']:.0f}; {importance['distinct_draws']} distinct draws among the "
            "resampled. The pair plot shows the resampled draws."
        )
        + "</p>"
    )


def _diagnostics(run: RunFolder, idata, summary, loo, figures: Figures) -> list[str]:
    """The sampler's diagnostics, the fit against the data and the error model."""
    return [
        "<h2>Diagnostics</h2>",
        _sampler_line(summary),
        *figures.shown("trace", "rank", "pair", "energy"),
        "<h2>Fit against the data</h2>",
        *figures.shown("predictive", "residual_map", "pareto_k"),
        "<h2>Error model</h2>",
        error_model_table(summary),
        *figures.shown("loo_pit", "spread_check"),
        loo_table(loo),
        variants_comparison(run, idata),
    ]


def _products(run: RunFolder, bands, exports, traces, figures: Figures) -> list[str]:
    """The products (TIS, maps, exports) and the studies written beside the run."""
    return [
        "<h2>Products</h2>",
        *figures.shown("tis_band", "hemisphere"),
        tis_table(bands) if "tis" in bands else "",
        *export_section(exports, figures.shown("export")),
        *compare_section(run),
        *sensitivity_section(run),
        *design_section(run),
        *instruments_section(run),
        *(
            [
                "<h2>Ray-tracing validation (Sec. 6)</h2>",
                raytrace_table(traces),
                *figures.shown("raytrace", "detector_images"),
            ]
            if traces
            else []
        ),
    ]


def _studies_line(run: RunFolder) -> str:
    """One line naming the studies this run left out and how to add them (``studies.json``
    of ``run``; empty for a ``posterior`` folder)."""
    left_out = (run.studies() or {}).get("not_run", [])
    if not left_out:
        return ""
    return (
        "<p class='studies'>Not run: "
        + _html.escape("; ".join(left_out))
        + ". Add them with a <code>[studies]</code> table in the scene, or all at once with "
        "<code>brdf-infer run --full</code>.</p>"
    )
