"""``brdf-infer report RUN_DIR``: diagnostics first, then fit against data, then products."""

from __future__ import annotations

import json
import time
import warnings
from pathlib import Path

import numpy as np

from brdf_infer._arviz import az
from brdf_infer._atomic import atomic_write_bytes
from brdf_infer._outlock import require_complete, writing
from brdf_infer.compare import COMPARE_FILE
from brdf_infer.errors import BadInputError
from brdf_infer.model import REFERENCE_FAMILY, fold_statement
from brdf_infer.posterior import (
    BANDS_FILE,
    POSTERIOR_FILE,
    SUMMARY_FILE,
    THRESHOLDS,
    draws_params,
    family_draws,
    run_fold,
)
from brdf_infer.report import _figures, _html, _noise
from brdf_infer.report._compare import compare_figure, compare_table_html
from brdf_infer.report._design import design_section
from brdf_infer.report._export import abg_table, load_exports, plot_export
from brdf_infer.report._instruments import MEANINGS, instruments_section
from brdf_infer.report._raytrace import figure_png, plot_detector_images, plot_raytrace
from brdf_infer.report._sensitivity import sensitivity_section
from brdf_infer.scene import load_scene
from brdf_infer.sensitivity import tis_angles
from brdf_infer.verdict import PARETO_K_LIMIT, Verdict

REPORT_FILE = "report.html"
RAYTRACE_FILE = "raytrace.json"
FIGURE_DIR = "figures"


def _load(run: Path):
    for name in (POSTERIOR_FILE, SUMMARY_FILE, BANDS_FILE):
        if not (run / name).is_file():
            raise BadInputError(
                f"no {name} here (run 'brdf-infer posterior --out DIR' first)", file=run
            )
    try:
        idata = az.from_netcdf(run / POSTERIOR_FILE)
        summary = json.loads((run / SUMMARY_FILE).read_text())
        bands = json.loads((run / BANDS_FILE).read_text())
    except (OSError, ValueError) as error:
        raise BadInputError(f"cannot read the run: {error}", file=run) from None
    if "verdict" not in summary:
        raise BadInputError(
            "no verdict in this run's summary (written by an earlier brdf_infer): run it again",
            file=run / SUMMARY_FILE,
        )
    return idata, summary, bands


def write_report(run: Path, progress=print) -> tuple[Path, Verdict]:
    """Write ``run/report.html`` and ``run/figures/*.png``; returns the path and the run's
    verdict (the one the run recorded, rendered as it stands).

    Raises:
        BadInputError: ``run`` is no complete run folder (:mod:`brdf_infer._outlock`: one
            being written, or left incomplete by a writer that stopped), or another process
            writes its report.
    """
    started = time.perf_counter()
    require_complete(run)
    loaded = _load(run)
    with writing(run, "report", option="RUN_DIR", adds=True):
        return _write_report(run, loaded, started, progress)


def _write_report(run: Path, loaded, started: float, progress) -> tuple[Path, Verdict]:
    idata, summary, bands = loaded
    attrs = idata.posterior.attrs
    scene = load_scene(attrs["scene_file"])
    member, physical = family_draws(idata.posterior)
    reference_model = member.name == REFERENCE_FAMILY
    rows = scene.load_measurements()
    with warnings.catch_warnings():  # high Pareto k are reported in the verdict instead
        warnings.simplefilter("ignore", UserWarning)
        loo = az.loo(idata, pointwise=True)
    verdict = Verdict.from_json(summary["verdict"])  # recorded when the run completed
    figures: list[tuple[str, str, object]] = []

    def add(name: str, caption: str, make) -> None:
        progress(f"  figure: {name}")
        figures.append((name, caption, figure_png(make())))

    reference = scene.outputs.reference_params
    add(
        "brdf_bands",
        "In-plane BRDF at the scene's incidence angles: posterior median, 68 % and 95 % bands, "
        "and the measured raw reflectance converted by Eq. (6)"
        + (f"; dashed: the reference parameter set '{reference}'" if reference else "")
        + ".",
        lambda: _figures.brdf_bands(bands, scene, rows),
    )
    add(
        "trace",
        "Trace plots in the sampler's well-conditioned coordinates (ln BRDF0, b1–b3, α, θs0 "
        "and the learned noise scales).",
        lambda: _figures.trace(idata),
    )
    add("rank", "Rank plots: chains that mix give flat histograms.", lambda: _figures.rank(idata))
    add("pair", "Pair plot; divergent transitions marked.", lambda: _figures.pair(idata))
    if "energy" in idata.sample_stats:
        add("energy", "NUTS energy plot.", lambda: _figures.energy(idata))
    add(
        "predictive",
        "Posterior predictive against the measured raw reflectance, per series (cf. Figs. 4, 6).",
        lambda: _figures.posterior_predictive(idata, rows.series),
    )
    pits = _loo_pits(run, summary)
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
    add("pareto_k", "PSIS-LOO Pareto k per measurement.", lambda: _figures.pareto_k(loo))
    if "tis" in bands:
        add(
            "tis_band",
            "TIS(θi): posterior median, 68 % and 95 % bands"
            + (", with the scene's reference points" if scene.outputs.tis_reference else "")
            + f"; {fold_statement(_tis_fold(bands))}.",
            lambda: _figures.tis_band(bands, scene.load_tis_reference()),
        )
    if scene.outputs.maps and (scene.model.out_of_plane or not reference_model):
        add(
            "hemisphere",
            "Hemisphere maps (cf. Fig. 9): posterior median BRDF on one logarithmic colour scale "
            "(top) and the relative width of its 95 % band (bottom); "
            f"{fold_statement(reference_model and run_fold(idata.posterior))}.",
            lambda: _figures.hemisphere_maps(member, physical),
        )
    exports = load_exports(run)
    shown = next((e for e in reversed(exports) if e["format"] == "zemax-bsdf"), None)
    if shown is not None and reference_model:
        tables = {f["kind"]: Path(f["path"]) for f in shown["files"] if f["kind"] != "draw"}
        fold = shown.get("fold", True)  # exports before the "fold" key folded by default
        add(
            "export",
            "Exported .BSDF tables read back as a ray tracer reads them, cut through the plane "
            "of incidence (black: median solid, 95 % bounds dotted), against the model's "
            f"posterior median and 95 % band evaluated directly (blue); {fold_statement(fold)}.",
            lambda: plot_export(tables, draws_params(idata.posterior), fold, scene.model.constants),
        )
    traces = _load_traces(run)
    if traces:
        add(
            "raytrace",
            "Ray-traced raw reflectance of the series II setup against the measurements "
            "(cf. Fig. 14): dPs/Pi through the detector aperture (crosses; shaded: 95 % band "
            "over posterior draws), the Eq. (6) point estimate (dotted) and the paper's image "
            "ratio over the signal square (small squares).",
            lambda: plot_raytrace(traces),
        )
        add(
            "detector_images",
            f"Simulated detector images for {traces[0]['params_source']} (cf. Fig. 13); the "
            "cyan square is the signal region of the image ratio.",
            lambda: plot_detector_images(_images(scene, rows, traces[0])),
        )
    for name, _, png in figures:
        atomic_write_bytes(run / FIGURE_DIR / f"{name}.png", png)

    table = az.summary(
        idata,
        var_names=[
            n for n in member.parameters if n not in summary["diagnostics"].get("fixed", [])
        ],
        round_to="none",
    )
    sections = [
        _html.verdict_box(verdict),
        "<p>Thresholds: "
        + _html.escape(
            f"R-hat ≤ {THRESHOLDS['r_hat']}, bulk and tail ESS ≥ {THRESHOLDS['ess']}, "
            f"no divergences, BFMI ≥ {THRESHOLDS['bfmi']}, Pareto k ≤ {PARETO_K_LIMIT}, "
            f"emcee ≥ {THRESHOLDS['tau_multiple']} autocorrelation times."
        )
        + "</p>",
        _result_box(summary, bands, tis_angles(scene, rows), member.name),
        _fold_note(bands) if "tis" in bands else "",
        *(_html.figure(png, caption) for name, caption, png in figures if name == "brdf_bands"),
        _studies_line(run),
        "<h2>The run</h2>",
        _html.table(
            ["item", "value"],
            [
                ["scene", f"{scene.name}: {scene.description}"],
                ["scene file", attrs["scene_file"]],
                ["model", member.name + ("" if reference_model else f" ({_units(member)})")],
                [
                    "instrument",
                    f"{attrs.get('instrument', 'point')}: "
                    + MEANINGS.get(attrs.get("instrument", "point"), ""),
                ],
                ["measurements", f"{scene.measurements_path} ({len(rows)} rows)"],
                ["sampler", f"{attrs['sampler']} {attrs['settings']}"],
                ["seed", attrs["seed"]],
                ["options", json.dumps(summary.get("options", {}))],
                [
                    "Eq. (10) folding (the scene's [model] fold)",
                    fold_statement(reference_model and run_fold(idata.posterior)),
                ],
                ["versions", attrs["versions"]],
                [
                    "wall time",
                    f"{summary['seconds']['total']:.1f} s "
                    f"(sampling {summary['seconds']['sampling']:.1f} s)",
                ],
                ["created", attrs.get("created", "")],
            ],
        ),
        "<h3>Priors</h3>",
        "<p>Each prior is on the coordinate named (the sampler's well-conditioned one).</p>",
        _priors_table(scene) if reference_model else _family_priors_table(member),
        "<h3>Data</h3>",
        _html.table(
            ["series", "sample", "θi [deg]", "θs [deg]", "R [-]", "σ_R [-]"],
            [
                [s, m, f"{i:g}", f"{t:g}", f"{r:.3e}", "–" if e is None else f"{e:.2e}"]
                for s, m, i, t, r, e in zip(
                    rows.series,
                    rows.sample,
                    rows.theta_i_deg,
                    rows.theta_s_deg,
                    rows.reflectance,
                    [None] * len(rows) if rows.reflectance_err is None else rows.reflectance_err,
                    strict=True,
                )
            ],
        ),
        "<h2>ArviZ summary (physical units)</h2>",
        _html.table(
            ["parameter", *table.columns],
            [[name, *(f"{v:.4g}" for v in table.loc[name])] for name in table.index],
        ),
        "<h2>Diagnostics</h2>",
        *(
            _html.figure(png, caption)
            for name, caption, png in figures
            if name in ("trace", "rank", "pair", "energy")
        ),
        "<h2>Fit against the data</h2>",
        *(
            _html.figure(png, caption)
            for name, caption, png in figures
            if name in ("predictive", "pareto_k")
        ),
        "<h2>Error model</h2>",
        _error_model_table(summary),
        *(
            _html.figure(png, caption)
            for name, caption, png in figures
            if name in ("loo_pit", "spread_check")
        ),
        _html.table(
            ["PSIS-LOO", "value"],
            [
                ["elpd_loo", f"{loo.elpd_loo:.2f} ± {loo.se:.2f}"],
                ["p_loo", f"{loo.p_loo:.2f}"],
                [
                    f"points with k > {PARETO_K_LIMIT}",
                    int(np.sum(np.asarray(loo.pareto_k) > PARETO_K_LIMIT)),
                ],
            ],
        ),
        _comparison(run, idata),
        "<h2>Products</h2>",
        *(
            _html.figure(png, caption)
            for name, caption, png in figures
            if name in ("tis_band", "hemisphere")
        ),
        _tis_table(bands) if "tis" in bands else "",
        *_export_section(exports, figures),
        *_compare_section(run),
        *sensitivity_section(run),
        *design_section(run),
        *instruments_section(run),
        *(
            ["<h2>Ray-tracing validation (Sec. 6)</h2>", _raytrace_table(traces)]
            + [
                _html.figure(png, caption)
                for name, caption, png in figures
                if name in ("raytrace", "detector_images")
            ]
            if traces
            else []
        ),
    ]
    title = f"brdf_infer report: {scene.name}, {member.name} ({attrs['sampler']})"
    document = _html.page(title, sections)
    path = atomic_write_bytes(run / REPORT_FILE, document.encode())
    progress(f"report written in {time.perf_counter() - started:.1f} s")
    return path, verdict


def _studies_line(run: Path) -> str:
    """One line naming the studies this run left out and how to add them (``studies.json``
    of ``run``; empty for a ``posterior`` folder)."""
    path = run / "studies.json"
    if not path.exists():
        return ""
    left_out = json.loads(path.read_text()).get("not_run", [])
    if not left_out:
        return ""
    return (
        "<p class='studies'>Not run: "
        + _html.escape("; ".join(left_out))
        + ". Add them with a <code>[studies]</code> table in the scene, or all at once with "
        "<code>brdf-infer run --full</code>.</p>"
    )


def _compare_section(run: Path) -> list[str]:
    """The model comparison (``compare.json`` of ``brdf-infer compare --out RUN`` or ``run``)."""
    path = run / COMPARE_FILE
    if not path.is_file():
        return []
    payload = json.loads(path.read_text())
    best = payload["models"][0]["name"]
    return [
        "<h2>Model comparison (PSIS-LOO)</h2>",
        f"<p>Every family sampled by NUTS on the same rows and error model; ranked by the "
        f"leave-one-out log predictive density (higher is better). Best: <b>{best}</b>. A "
        f"difference is clear when Δelpd is several times its se. A family whose sampler "
        f"diagnostics fail (R-hat > {THRESHOLDS['r_hat']}, bulk ESS < {THRESHOLDS['ess']}, "
        f"divergences) is marked: its draws may not represent its posterior, so its rank is "
        f"not to be trusted.</p>",
        compare_table_html(payload),
        _html.figure(
            compare_figure(payload),
            "PSIS-LOO of each family (elpd_loo ± se, best on top) and its TIS(70°) band.",
        ),
    ]


def _export_section(exports: list[dict], figures) -> list[str]:
    """The Export section: where the files are, the table plot and the ABg table."""
    if not exports:
        return []
    parts = ["<h2>Export</h2>"]
    for entry in exports:
        names = ", ".join(Path(f["path"]).name for f in entry["files"][:6])
        more = len(entry["files"]) - 6
        folding = f"; {fold_statement(entry['fold'])}" if "fold" in entry else ""
        parts.append(
            f"<p>{_html.escape(entry['format'])} in <code>{_html.escape(entry['folder'])}</code>: "
            f"{_html.escape(names)}{f' and {more} more' if more > 0 else ''}"
            f"{_html.escape(folding)}</p>"
        )
        if entry["format"] == "abg" and entry.get("rows"):
            parts.append(abg_table(entry["rows"]))
    parts += [_html.figure(png, caption) for name, caption, png in figures if name == "export"]
    return parts


SPREAD_VARIANT = "spread"
PRIOR_COORDINATES = {
    "brdf0": "ln BRDF0 [ln sr⁻¹]",
    "a1": "b1 = a1·90² [-]",
    "a2": "b2 = a2·90^(1+α) [-]",
    "a3": "b3 = a3·90^(2+α) [-]",
    "alpha": "α [-]",
    "theta_s0": "θs0 [deg]",
}


def _priors_table(scene) -> str:
    rows = [
        [name, PRIOR_COORDINATES[name], _prior_text(prior)] for name, prior in scene.priors.items()
    ]
    return _html.table(["parameter", "prior on the coordinate", "prior"], rows)


def _units(member) -> str:
    return ", ".join(f"{name} [{member.units[name]}]" for name in member.parameters)


def _prior_text(prior) -> str:
    if prior.fixed:
        return f"fixed at {prior.value:g}"
    if prior.kind == "normal":
        return f"N({prior.loc:g}, {prior.scale:g})"
    if prior.kind == "uniform":
        return f"U[{prior.lower:g}, {prior.upper:g}]"
    bounds = (
        f"{'-inf' if prior.lower is None else f'{prior.lower:g}'}, "
        f"{'inf' if prior.upper is None else f'{prior.upper:g}'}"
    )
    return f"N({prior.loc:g}, {prior.scale:g}) on [{bounds}]"


def _family_priors_table(member) -> str:
    return _html.table(
        ["coordinate", "meaning", "prior"],
        [[c.site, c.description, _prior_text(c.prior)] for c in member.coordinates],
    )


def _result_box(summary: dict, bands: dict, angles, model: str = REFERENCE_FAMILY) -> str:
    """The answer first: TIS at ``angles`` (the scene's incidence angles and the article's 70°)
    and π·BRDF0 (``strumik2024``), 95 % intervals."""
    rows = []
    if "tis" in bands:
        grid = np.asarray(bands["tis"]["theta_i_deg"])
        for angle in angles:
            values = [np.interp(angle, grid, bands["tis"][k]) for k in ("median", "lo95", "hi95")]
            rows.append(
                [
                    f"TIS(θi = {angle:g}°)",
                    f"{100 * values[0]:.2f} %",
                    f"{100 * values[1]:.2f} – {100 * values[2]:.2f} %",
                ]
            )
    brdf0 = summary.get("pi_brdf0")
    if brdf0 is not None:
        rows.append(
            [
                "π·BRDF0 (near-normal TIS, Sec. 7)",
                f"{100 * brdf0['median']:.2f} %",
                f"{100 * brdf0['lo95']:.2f} – {100 * brdf0['hi95']:.2f} %",
            ]
        )
    return (
        '<div class="result"><h2>Result'
        + ("" if model == REFERENCE_FAMILY else f" ({_html.escape(model)})")
        + "</h2>"
        + _html.table(["quantity", "posterior median", "95 % credible interval"], rows)
        + "</div>"
    )


def _loo_pits(run: Path, summary: dict) -> dict[str, tuple[list, float]]:
    """Error model name → (LOO-PIT values, KS p) of this run and of its spread variant."""
    pits = {}
    if "predictive" in summary:
        name = summary.get("error_model", {}).get("model", "this run")
        pits[f"{name} (this run)"] = (
            summary["predictive"]["loo_pit"],
            summary["predictive"]["loo_pit_ks_p"],
        )
    variant = run / "variants" / SPREAD_VARIANT / SUMMARY_FILE
    if variant.is_file():
        other = json.loads(variant.read_text())
        pits["spread (earlier model)"] = (
            other["predictive"]["loo_pit"],
            other["predictive"]["loo_pit_ks_p"],
        )
    return pits


def _error_model_table(summary: dict) -> str:
    """The noise sources of the run's error model with their sizes."""
    errors = summary.get("error_model")
    if not errors:
        return ""
    if errors["model"] == "spread":
        return (
            "<p>The earlier spread model: independent rows with σ² = "
            f"{errors['reflectance_rel']:g}² + s(θi)², s the inter-sample spread of ln R.</p>"
        )
    noise = summary.get("noise", {})

    def learned(name: str) -> str:
        if name not in noise:
            return "off"
        value = noise[name]
        return f"{value['median']:.3f} (95 %: {value['lo95']:.3f}–{value['hi95']:.3f}), learned"

    repeatability = (
        learned("repeatability")
        if errors["repeatability"] == "learned"
        else f"{errors['repeatability']:g}, fixed"
    )
    calibration = errors.get("calibration", "none")
    calibration = (
        f"{errors['calibration_rel']:g} {calibration.replace('_', ' ')}, fixed"
        if calibration != "none"
        else "off"
    )
    angles = errors["propagate_angles"]
    images = errors["images_per_row"]
    if isinstance(images, dict):
        images = ", ".join(f"{n} ({name})" for name, n in images.items()) + ", else 1"
    coupling = {"camera_follows": "θs + ε", "camera_fixed": "θs − ε"}.get(
        errors.get("rotation_coupling", ""), ""
    )
    rows = [
        [
            "value noise e_i",
            f"σ of each row ÷ √n, n = {images} images (row's reflectance_err, else "
            f"reflectance_rel {errors['reflectance_rel']:g})",
        ],
        ["repeatability ν_i (per row)", repeatability],
        [
            "sample-to-sample u_j (per sample)",
            learned("sample_sd") if errors["hierarchical"] else "off",
        ],
        ["calibration κ (per reference measurement)", calibration],
        [
            "sample rotation ε (per series, sample, θi)",
            f"{errors['rotation_deg']:g}° through ln R ({errors['angle_method']}): θi + ε, "
            f"{coupling} ({errors.get('rotation_coupling', '')})"
            if angles
            else "off",
        ],
        [
            "camera position η (per row)",
            f"{errors['camera_deg']:g}° through ln R ({errors['angle_method']})"
            if angles
            else "off",
        ],
    ]
    return "<p>Every noise source enters once (sizes in ln R):</p>" + _html.table(
        ["source", "size"], rows
    )


def _load_traces(run: Path) -> list[dict]:
    """The ray traces a run wrote (``raytrace.json``), possibly none."""
    path = run / RAYTRACE_FILE
    if not path.is_file():
        return []
    try:
        return json.loads(path.read_text())["traces"]
    except (OSError, ValueError, KeyError) as error:
        raise BadInputError(f"cannot read the ray traces: {error}", file=path) from None


def _images(scene, rows, trace: dict) -> dict:
    from brdf_infer.params import Params
    from brdf_infer.raytrace import simulate_images

    return simulate_images(scene, rows, Params(**trace["params"]), seed=trace["seed"])


def _raytrace_table(traces: list[dict]) -> str:
    header = ["θi [deg]", "δ [deg]", "measured [-]"]
    for trace in traces:
        header += [f"simulated, {trace['params_source']} [-]", "simulated / measured"]
    header += ["point estimate Eq. (6) [-]", "image ratio [-]"]
    table = []
    for k, row in enumerate(traces[0]["rows"]):
        cells = [f"{row['theta_i_deg']:g}", f"{row['delta_deg']:+g}", f"{row['measured']:.3e}"]
        for trace in traces:
            other = trace["rows"][k]
            text = f"{other['simulated']:.3e} ± {other['mc_se']:.1e}"
            if "band" in other:
                text += f" (95 %: {other['band']['lo95']:.2e}–{other['band']['hi95']:.2e})"
            cells += [text, f"{other['simulated'] / row['measured']:.3f}"]
        cells += [f"{row['point_estimate']:.3e}", f"{row['image_ratio']:.3e}"]
        table.append(cells)
    note = (
        f"<p>{traces[0]['rays']} rays per configuration ({traces[0]['estimator']} estimator). "
        "Simulated = power scattered through the detector aperture over the incident power, "
        "the quantity Eq. (6) converts; image ratio = scattered over reference image summed "
        "over the signal square, as the paper's Eq. (2) processes the CCD images.</p>"
    )
    return note + _html.table(header, table)


def _indices_of(grid: list[float], angles: tuple[float, ...]) -> list[int]:
    """Positions in a band's θi grid of those ``angles`` it holds."""
    return [list(grid).index(angle) for angle in angles if angle in grid]


def _tis_fold(bands: dict) -> bool:
    """Eq. (10) in the run's TIS band: its ``"fold"`` (the scene's switch); a run written
    before that key had its TIS folded always."""
    return bands.get("fold", True)


def _fold_note(bands: dict) -> str:
    """One line under the result: whether its TIS includes Eq. (10), and how to change it."""
    fold = _tis_fold(bands)
    change = (
        "leave out [model] fold (or set it false) in the scene for the physical BRDF"
        if fold
        else "the article's Table 3 includes it: set [model] fold = true in the scene, or "
        "pass --fold to tis and export"
    )
    return f"<p class='fold'>{_html.escape(fold_statement(fold))}; {_html.escape(change)}.</p>"


def _tis_table(bands: dict) -> str:
    band = bands["tis"]
    chosen = _indices_of(band["theta_i_deg"], (0.0, 5.0, 30.0, 50.0, 70.0, 80.0))
    rows = [
        [
            f"{band['theta_i_deg'][i]:g}",
            *(f"{100 * band[k][i]:.3f}" for k in ("median", "lo68", "hi68", "lo95", "hi95")),
        ]
        for i in chosen
    ]
    return (
        "<h3>TIS [%]</h3>"
        + f"<p>{_html.escape(fold_statement(_tis_fold(bands)))}.</p>"
        + _html.table(["θi [deg]", "median", "16 %", "84 %", "2.5 %", "97.5 %"], rows)
    )


def _comparison(run: Path, idata) -> str:
    """LOO comparison with model variants stored under ``run/variants/NAME``."""
    variants = {"this run": idata}
    for folder in sorted((run / "variants").glob("*/")) if (run / "variants").is_dir() else []:
        if (folder / POSTERIOR_FILE).is_file():
            variants[folder.name] = az.from_netcdf(folder / POSTERIOR_FILE)
    if len(variants) < 2:
        return "<p>No model variants in this run to compare (variants/NAME/posterior.nc).</p>"
    compared = az.compare(variants)
    return "<h3>Model variants (PSIS-LOO)</h3>" + _html.table(
        ["variant", "rank", "elpd_loo", "p_loo", "elpd_diff", "weight", "se", "dse"],
        [
            [
                name,
                int(r["rank"]),
                f"{r['elpd_loo']:.2f}",
                f"{r['p_loo']:.2f}",
                f"{r['elpd_diff']:.2f}",
                f"{r['weight']:.2f}",
                f"{r['se']:.2f}",
                f"{r['dse']:.2f}",
            ]
            for name, r in compared.iterrows()
        ],
    )


EXAMPLE_FIGURES = ("brdf_bands", "tis_band", "hemisphere", "predictive", "raytrace", "instrument")
STUDY_FIGURES = (
    "compare",
    "sensitivity",
    "design",
)  # written by the studies into the run folder itself


def write_example(run: Path, example: Path) -> Path:
    """A small committed example: the key PNGs of ``run`` and a README with its verdict."""
    summary = json.loads((run / SUMMARY_FILE).read_text())
    verdict = Verdict.from_json(summary["verdict"])
    bands = json.loads((run / BANDS_FILE).read_text())
    sources = [run / FIGURE_DIR / f"{name}.png" for name in EXAMPLE_FIGURES]
    sources += [run / f"{name}.png" for name in STUDY_FIGURES]
    names = [source.stem for source in sources if source.is_file()]
    for source in sources:
        if source.is_file():
            atomic_write_bytes(example / source.name, source.read_bytes())
    diagnostics = summary["diagnostics"]
    band = bands.get("tis")
    studies_file = run / "studies.json"
    studies = json.loads(studies_file.read_text()).get("run", []) if studies_file.exists() else []
    lines = [
        f"# Example report: scene `{summary['scene']}` ({summary['sampler']})",
        "",
        "Regenerate with `./dev run --full --example reports/example` (every study the scene can",
        "run; the full HTML report is written to `reports/lya/report.html`, which is not",
        "committed).",
        "",
        "**Studies run beside the posterior:** "
        + ("; ".join(studies) if studies else "none (the scene's one posterior)")
        + ".",
        "",
        f"**Verdict:** {verdict.text} (max R-hat {diagnostics['r_hat_max']:.3f}, min "
        f"bulk/tail ESS {diagnostics['ess_bulk_min']:.0f}/{diagnostics['ess_tail_min']:.0f}, "
        f"{diagnostics.get('divergences', 0)} divergences).",
        "",
        *(
            [
                "| θi [deg] | TIS median [%] | 68 % [%] | 95 % [%] |",
                "|---|---|---|---|",
                *(
                    f"| {band['theta_i_deg'][i]:g} | {100 * band['median'][i]:.2f} | "
                    f"{100 * band['lo68'][i]:.2f}–{100 * band['hi68'][i]:.2f} | "
                    f"{100 * band['lo95'][i]:.2f}–{100 * band['hi95'][i]:.2f} |"
                    for i in _indices_of(band["theta_i_deg"], (0.0, 30.0, 50.0, 70.0, 80.0))
                ),
                "",
                f"TIS: {fold_statement(_tis_fold(bands))}.",
            ]
            if band
            else []
        ),
        "",
        *(f"![{name}]({name}.png)" for name in names),
        "",
    ]
    return atomic_write_bytes(example / "README.md", "\n".join(lines).encode())
