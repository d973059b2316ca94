"""Figures and HTML of a PSIS-LOO model comparison (``compare.json``): the folder the figure is
written to with the result, and the report's Model comparison section."""

from __future__ import annotations

import io
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter, LogLocator, MaxNLocator, NullFormatter

from brdf_infer._internal import arviz as az
from brdf_infer.posterior import THRESHOLDS
from brdf_infer.report._html import escape
from brdf_infer.report._html import figure as html_figure
from brdf_infer.runs.folder import COMPARE_FIGURE, COMPARE_FILE, RunFolder
from brdf_infer.studies.compare import ComparisonResult
from brdf_infer.verdict import PARETO_K_LIMIT

UNTRUSTED = "sampler diagnostics fail"
TEXT_SIZE = 9  # both panels' labels (ArviZ's default for a 10-in figure is twice that)
UNTRUSTED_STYLE = {"fmt": "o", "color": "tab:red", "mfc": "white", "label": UNTRUSTED}


def label(row: dict[str, Any]) -> str:
    """A family's name, marked where its sampler diagnostics fail (its rank is then not to be
    trusted)."""
    return row["name"] if row["sampler_ok"] else f"{row['name']} ({UNTRUSTED})"


def compare_frame(payload: dict[str, Any]) -> pd.DataFrame:
    """The comparison as ArviZ's ``compare`` table (best first)."""
    rows = payload["models"]
    return pd.DataFrame(
        {
            "rank": list(range(len(rows))),
            "elpd_loo": [row["elpd_loo"] for row in rows],
            "p_loo": [row["p_loo"] for row in rows],
            "elpd_diff": [row["d_elpd"] for row in rows],
            "weight": [row["weight"] for row in rows],
            "se": [row["se"] for row in rows],
            "dse": [row["dse"] for row in rows],
            "warning": [
                row["pareto_k_max_after_refit"] > row.get("pareto_k_limit", PARETO_K_LIMIT)
                for row in rows
            ],
            "scale": ["log"] * len(rows),
        },
        index=[label(row) for row in rows],
    )


def compare_figure(payload: dict[str, Any], dpi: int = 90) -> bytes:
    """PNG: ArviZ's compare plot (elpd_loo ± se, Δelpd ± dse) beside each family's TIS(70°);
    a family whose sampler diagnostics fail is marked in both."""
    buffer = io.BytesIO()
    compare_plot(payload).savefig(buffer, format="png", dpi=dpi)
    return buffer.getvalue()


def compare_plot(payload: dict[str, Any]) -> Figure:
    """The figure of :func:`compare_figure`, laid out (10 in wide, 0.6 in per family + 1.8 in
    high): one text size in both panels; the TIS panel's rows level with the compare plot's
    (named there once; a family whose sampler diagnostics fail drawn hollow and in red, as its
    legend says), its axis in percent with at most five plain labels (:func:`tis_axis`); every
    label inside the figure."""
    models = payload["models"]
    figure = Figure(figsize=(10.0, 0.6 * len(models) + 1.8), layout="constrained")
    left, right = figure.subplots(1, 2, sharey=True, gridspec_kw={"width_ratios": [3, 2]})
    with warnings.catch_warnings():  # ArviZ's own use of a deprecated pandas keyword
        warnings.simplefilter("ignore")
        az.plot_compare(
            compare_frame(payload), ax=left, insample_dev=False, legend=False, textsize=TEXT_SIZE
        )
    left.set_xlabel("elpd_loo (higher is better) [nats]", fontsize=TEXT_SIZE)
    left.set_ylabel("ranked models", fontsize=TEXT_SIZE)
    left.set_title("PSIS-LOO, best on top: elpd_loo ± se", fontsize=TEXT_SIZE)
    positions = left.get_yticks()  # ArviZ's rows, best on top, in the payload's order
    bands = 100 * np.array(
        [[row["tis70"][key] for key in ("median", "lo95", "hi95")] for row in models]
    )
    for ok, style in ((True, {"fmt": "o"}), (False, UNTRUSTED_STYLE)):
        rows = np.array([row["sampler_ok"] is ok for row in models])
        if rows.any():
            right.errorbar(
                bands[rows, 0],
                positions[rows],
                xerr=np.abs(bands[rows, 1:] - bands[rows, :1]).T,
                **style,
            )
    if not all(row["sampler_ok"] for row in models):
        right.legend(fontsize=TEXT_SIZE, loc="best")
    right.tick_params(labelleft=False, labelsize=TEXT_SIZE)
    tis_axis(right, bands[:, 1].min(), bands[:, 2].max())
    right.set_xlabel("TIS(70°) [%]: median, 95 % interval", fontsize=TEXT_SIZE)
    right.set_title("TIS(70°) of each family", fontsize=TEXT_SIZE)
    right.grid(alpha=0.3)
    return figure


def tis_axis(axes, low: float, high: float) -> None:
    """The TIS axis from ``low`` to ``high`` [%]: linear where the bands span less than a
    decade, else logarithmic; either way at most five major labels in plain numbers (a log
    axis's minor ticks unlabelled: on a narrow span their "4×10⁰" labels overran each other)."""
    if high > 10 * low > 0:
        axes.set_xscale("log")
        axes.xaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0), numticks=5))
    else:
        axes.xaxis.set_major_locator(MaxNLocator(nbins=5))
    axes.xaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
    axes.xaxis.set_minor_formatter(NullFormatter())


def compare_table_html(payload: dict[str, Any]) -> str:
    """The comparison as an HTML table (best first), each family's sampler diagnostics next to
    its rank; a family whose diagnostics fail is marked not to be trusted."""
    head = (
        "<tr><th>model</th><th>elpd_loo ± se</th><th>Δelpd ± dse</th><th>weight</th>"
        "<th>p_loo</th><th>Pareto k max</th><th>R-hat max</th><th>bulk ESS min</th>"
        "<th>divergences</th><th>sampler</th><th>TIS(70°) [%] (95 %)</th></tr>"
    )
    body = "".join(
        f"<tr><td>{escape(row['name'])}</td><td>{row['elpd_loo']:.1f} ± {row['se']:.1f}</td>"
        f"<td>{row['d_elpd']:.1f} ± {row['dse']:.1f}</td><td>{row['weight']:.2f}</td>"
        f"<td>{row['p_loo']:.1f}</td><td>{row['pareto_k_max']:.2f}</td>"
        f"<td>{row['r_hat_max']:.3f}</td><td>{row['ess_bulk_min']:.0f}</td>"
        f"<td>{row['divergences']}</td>"
        + (
            "<td>ok</td>"
            if row["sampler_ok"]
            else f"<td class='fail'>{UNTRUSTED} ({escape(', '.join(row['sampler_failures']))}): "
            "rank not to be trusted</td>"
        )
        + f"<td>{100 * row['tis70']['median']:.2f} ({100 * row['tis70']['lo95']:.2f}–"
        f"{100 * row['tis70']['hi95']:.2f})</td></tr>"
        for row in payload["models"]
    )
    return f"<table>{head}{body}</table>"


def write_comparison(out: Path, result: ComparisonResult) -> list[Path]:
    """compare.json and ArviZ's compare plot (compare.png) into ``out``, atomically."""
    folder = RunFolder(out)
    folder.path.mkdir(parents=True, exist_ok=True)
    return [
        folder.write_json(COMPARE_FILE, result.as_json()),
        folder.write_bytes(COMPARE_FIGURE, compare_figure(result.as_json())),
    ]


def compare_section(run: RunFolder) -> list[str]:
    """The model comparison (``compare.json`` of ``brdf-infer compare --out RUN`` or ``run``)."""
    payload = run.compare()
    if payload is None:
        return []
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
        html_figure(
            compare_figure(payload),
            "PSIS-LOO of each family (elpd_loo ± se, best on top) and its TIS(70°) band.",
        ),
    ]
