"""The report's answer: TIS and π·BRDF0 with their 95 % intervals, the TIS table, and whether
the TIS includes the Eq. (10) folding."""

from __future__ import annotations

import numpy as np

from brdf_infer.model import ModelFamily, fold_statement
from brdf_infer.report import _html
from brdf_infer.runs.records import Bands, PosteriorSummary
from brdf_infer.verdict import TARGET_WORDS, quantity_words, value_words, width_words


def _percent_interval(low: float, high: float) -> str:
    return f"{100 * low:.2f} – {100 * high:.2f} %"


WIDTH_LEGEND = (
    "<p class='fold'>What carries the width: each assumption of the model with the part of "
    "the 95 % interval's variance it carries, 1 − (width without it / width)² (independent "
    "sources add in quadrature), ± its Monte Carlo error, and the interval without it; where "
    "the interval is wider without it, that interval and no share (the alternative is another "
    "model, not a part of this width). Δelpd: PSIS-LOO of the alternative less the run's, ± "
    "its standard error (negative: the data prefer the run's model). Computed from the run's "
    "draws (Pareto-smoothed importance reweighting, or a new posterior where that is "
    "unreliable). <em>Prior alone</em>: the 95 % interval before the data.</p>"
)


def reference_lines(summary: PosteriorSummary) -> str:
    """Where each of the scene's published values falls in the posterior."""
    entries = summary.get("reference", [])
    if not entries:
        return ""
    items = "".join(
        f"<li>{_html.escape(quantity_words(r['quantity']))} = "
        f"{_html.escape(value_words(r['quantity'], r['value']))} "
        f"({_html.escape(r['source'])}): posterior quantile {r['posterior_quantile']:.3f}"
        + (f" ± {r['quantile_mcse']:.3f}" if "quantile_mcse" in r else "")
        + f", {_place_html(r)} the 95 % interval</li>"
        for r in entries
    )
    return (
        "<p>Published values placed in this posterior (why they can differ: the article "
        "fixes α and θs0, fits ln BRDF by unweighted regression and treats no noise source "
        "apart; "
        "docs/instruments.md, “The answer and the article”):</p>"
        f"<ul>{items}</ul>"
    )


def _place_html(reference: dict) -> str:
    """Where a reference value falls, emphasised unless inside."""
    place = reference.get("place", "inside" if reference["inside95"] else "outside")
    words = {"inside": "inside", "outside": "outside", "at the edge": "at the edge of"}[place]
    return words if place == "inside" else f"<strong>{words}</strong>"


def result_box(summary: PosteriorSummary, bands: Bands, angles, member: ModelFamily) -> str:
    """The answer first: TIS at ``angles`` (the scene's incidence angles and the article's 70°)
    and π·BRDF0 (Eq. 7's family), 95 % intervals, each with what carries its width
    (:func:`width_words`); then the published reference values; another family is named in
    the heading."""
    rows = []
    widths = summary.get("width", {})
    if "tis" in bands:
        grid = np.asarray(bands["tis"]["theta_i_deg"])
        for angle in angles:
            values = [np.interp(angle, grid, bands["tis"][k]) for k in ("median", "lo95", "hi95")]
            rows.append(
                [
                    f"TIS(θi = {angle:g}°)",
                    f"{100 * values[0]:.2f} %",
                    _percent_interval(values[1], values[2]),
                    width_words(widths.get(name := f"tis_{float(angle):g}deg"), name),
                ]
            )
    brdf0 = summary.get("pi_brdf0")
    if brdf0 is not None:
        rows.append(
            [
                "π·BRDF0 (near-normal TIS, Sec. 7)",
                f"{100 * brdf0['median']:.2f} %",
                _percent_interval(brdf0["lo95"], brdf0["hi95"]),
                width_words(widths.get("pi_brdf0"), "pi_brdf0"),
            ]
        )
    target = summary.get("target", "coating")
    carrier = (
        "what carries the width" if target == "coating" else "what carries the coating's width"
    )
    return (
        '<div class="result"><h2>Result'
        + ("" if member.paper_parameters else f" ({_html.escape(member.name)})")
        + f" for {_html.escape(TARGET_WORDS[target])}</h2>"
        + _html.table(["quantity", "posterior median", "95 % credible interval", carrier], rows)
        + targets_table(summary.get("targets"))
        + (WIDTH_LEGEND if widths else "")
        + reference_lines(summary)
        + "</div>"
        + campaigns_table(summary)
    )


def campaigns_table(summary: dict) -> str:
    """Each calibration factor learned (:mod:`brdf_infer.posterior._campaigns`) and, for a
    pooled scene, each campaign: its file, rows, own error settings, elpd with its standard
    error and LOO-PIT p; empty where the run has neither."""
    campaigns = summary.get("campaigns") or {}
    effects = summary.get("calibration_effects") or []
    html = ""
    if campaigns:
        rows = [
            [
                name,
                entry["measurements"],
                f"{entry['rows']} rows, {len(entry['samples'])} sample(s)",
                ", ".join(f"{k} = {v}" for k, v in entry["errors"].items()) or "the scene's",
                f"{entry['elpd_loo']:.1f} ± {entry['se'] or 0:.1f}",
                f"{entry['loo_pit_ks_p']:.2g}",
            ]
            for name, entry in campaigns.items()
        ]
        html += "<h3>Campaigns pooled</h3>" + _html.table(
            ["campaign", "file", "rows", "own [errors]", "elpd_loo ± se", "LOO-PIT p"], rows
        )
    if effects:
        rows = [
            [
                entry["name"],
                f"{100 * entry['prior_sd']:.3g} %",
                f"{100 * entry['median']:+.2f} % ({100 * entry['lo95']:+.2f} to "
                f"{100 * entry['hi95']:+.2f} %)",
                "–" if entry["sd_ratio"] is None else f"{entry['sd_ratio']:.2f}",
            ]
            for entry in effects
        ]
        html += (
            "<h3>Calibration factors learned</h3>"
            + _html.table(
                ["group", "σ_cal (prior, ln R)", "κ median (95 %), ln R", "posterior sd / σ_cal"],
                rows,
            )
            + "<p class='fold'>The rows locate the differences between calibration groups, "
            "not their common level (the coating's amplitude takes it): a ratio near 1 is a "
            "factor only its prior sets.</p>"
        )
    return html


def targets_table(targets: dict | None) -> str:
    """The three answers side by side (:mod:`brdf_infer.posterior._targets`): each target's
    question, TIS(70°) and π·BRDF0 with 95 % intervals, the one the bands describe first, and
    where τ comes from; empty for a run written before the record."""
    if not targets:
        return ""
    chosen = targets["chosen"]
    order = [chosen, *(name for name in TARGET_WORDS if name != chosen)]
    heads = {"tis_70deg": "TIS(70°), 95 %", "pi_brdf0": "π·BRDF0, 95 %"}
    shown = [q for q in heads if any(targets[name].get(q) is not None for name in order)]
    rows = []
    for name in order:
        entry = targets[name]
        cells = [
            "–"
            if entry.get(quantity) is None
            else f"{100 * entry[quantity]['median']:.2f} % "
            f"({_percent_interval(entry[quantity]['lo95'], entry[quantity]['hi95'])})"
            for quantity in shown
        ]
        label = TARGET_WORDS[name] + (" (the bands)" if name == chosen else "")
        rows.append([label, entry["question"], *cells])
    return (
        "<h3>Which coating: the sample(s) measured, the coating, a new part</h3>"
        + _html.table(["for", "answers", *(heads[q] for q in shown)], rows)
        + f"<p class='fold'>τ, the spread between parts: {_html.escape(targets['tau_source'])}. "
        "A new part's band draws a new sample effect with τ: the one for a flight part's "
        "budget.</p>"
    )


def indices_of(grid: list[float], angles: tuple[float, ...]) -> list[int]:
    """Positions in a band's θi grid of those ``angles`` it holds."""
    return [list(grid).index(angle) for angle in angles if angle in grid]


def tis_fold(bands: Bands) -> bool:
    """Eq. (10) in the run's TIS band: its ``"fold"`` (the scene's switch); a run written
    before that key had its TIS folded always."""
    return bands.get("fold", True)


def fold_note(bands: Bands, article: bool = False) -> str:
    """One line under the result: whether its TIS includes Eq. (10), and how to change it;
    ``article``: the scene is compared with the article's parameters (``[outputs]
    reference_params``, the bundled scenes), whose Table 3 the line then names."""
    fold = tis_fold(bands)
    include = "set [model] fold = true in the scene, or pass --fold to tis and export"
    change = (
        "leave out [model] fold (or set it false) in the scene for the physical BRDF"
        if fold
        else f"the article's Table 3 includes it: {include}"
        if article
        else f"to include it, {include}"
    )
    return f"<p class='fold'>{_html.escape(fold_statement(fold))}; {_html.escape(change)}.</p>"


def tis_table(bands: Bands) -> str:
    band = bands["tis"]
    chosen = indices_of(band["theta_i_deg"], (0.0, 5.0, 30.0, 50.0, 70.0, 80.0))
    rows = [
        [
            f"{band['theta_i_deg'][i]:g}",
            *(f"{100 * band[k][i]:.3f}" for k in ("median", "lo68", "hi68", "lo95", "hi95")),
        ]
        for i in chosen
    ]
    return (
        "<h3>TIS [%]</h3>"
        + f"<p>{_html.escape(fold_statement(tis_fold(bands)))}.</p>"
        + _html.table(["θi [deg]", "median", "16 %", "84 %", "2.5 %", "97.5 %"], rows)
    )
