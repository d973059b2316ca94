"""The report's Export section: the exported .BSDF tables as a ray tracer reads them, against
the model evaluated directly, and the ABg table."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from brdf_infer.model import brdf_hemisphere, fold_statement
from brdf_infer.model.params import HemisphereConstants, Params
from brdf_infer.report import _html
from brdf_infer.report.export import read_bsdf
from brdf_infer.runs.folder import RunFolder

SHOWN_THETA_I_DEG = (0.0, 30.0, 60.0, 80.0)
_KIND_STYLE = {"lower95": ":", "median": "-", "upper95": ":", "params": "-"}
_TIS_QUANTILE_STYLE = {"tis_q025": ":", "tis_q500": "-", "tis_q975": ":"}  # red: real BRDFs
_MEANINGS = (
    "lower95/median/upper95.bsdf are pointwise envelopes (each cell's quantile over the "
    "draws), no BRDF of any draw: their hemisphere integrals are not the TIS quantiles; "
    "tis_q025/q500/q975.bsdf are the posterior draws at the 2.5/50/97.5 % TIS quantiles, "
    "real BRDFs that integrate to their TIS lines (tis_q975.bsdf: the conservative bound)"
)


def load_exports(run: RunFolder) -> list[dict]:
    """The exports recorded in ``run/exports.json`` whose files still exist."""
    entries = run.exports()
    return [e for e in entries if all(Path(f["path"]).is_file() for f in e["files"])]


def _in_plane_cut(contents, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Signed in-plane θs [deg] and BSDF of block ``k``: azimuth 180° gives θs = θi + r
    (forward), azimuth 0° gives θs = θi − r (through the normal to the backward side)."""
    theta_i = contents.theta_i_deg[k]
    table = contents.bsdf[0, k]
    forward = int(np.argmin(np.abs(contents.azimuth_deg - 180.0)))
    backward = int(np.argmin(np.abs(contents.azimuth_deg)))
    theta_s = np.concatenate([theta_i - contents.radial_deg, theta_i + contents.radial_deg])
    values = np.concatenate([table[backward], table[forward]])
    keep = np.abs(theta_s) < 90.0
    order = np.argsort(theta_s[keep])
    return theta_s[keep][order], values[keep][order]


def plot_export(
    tables: dict[str, Path], draws: Params, fold: bool, constants: HemisphereConstants
) -> plt.Figure:
    """In-plane cuts of the exported tables (lines) against the model's posterior median and
    95 % band evaluated directly (shaded; with Eq. 10 when the export has it, ``fold``), on
    polar axes: angle θs from the normal, radius log10 BRDF."""
    contents = {kind: read_bsdf(path) for kind, path in tables.items()}
    first = next(iter(contents.values()))
    shown = [
        int(np.argmin(np.abs(first.theta_i_deg - t)))
        for t in SHOWN_THETA_I_DEG
        if np.min(np.abs(first.theta_i_deg - t)) <= 5.0
    ]
    shown = sorted(set(shown))
    figure, axes = plt.subplots(
        1, len(shown), figsize=(3.6 * len(shown), 3.9), subplot_kw={"projection": "polar"}
    )
    axes = np.atleast_1d(axes)
    floor = None
    for ax, k in zip(axes, shown, strict=True):
        theta_i = first.theta_i_deg[k]
        theta_s = np.linspace(-89.5, 89.5, 359)
        phi = np.where(theta_s >= 0.0, 180.0, 0.0)
        batch = Params(*(np.asarray(v)[:, None] for v in draws))
        model = np.asarray(brdf_hemisphere(theta_i, np.abs(theta_s), phi, batch, fold, constants))
        low, median, high = np.log10(np.quantile(model, [0.025, 0.5, 0.975], axis=0))
        floor = np.floor(np.min(low)) - 0.5 if floor is None else floor
        angle = np.radians(theta_s)
        ax.fill_between(angle, low - floor, high - floor, color="tab:blue", alpha=0.25,
                        label="model 95 %")  # fmt: skip
        ax.plot(angle, median - floor, color="tab:blue", lw=2.5, alpha=0.5, label="model median")
        for kind, table in contents.items():
            cut_s, cut_v = _in_plane_cut(table, k)
            positive = cut_v > 0
            real = kind in _TIS_QUANTILE_STYLE
            ax.plot(
                np.radians(cut_s[positive]), np.log10(cut_v[positive]) - floor,
                color="tab:red" if real else "black",
                ls=(_TIS_QUANTILE_STYLE if real else _KIND_STYLE).get(kind, "-"), lw=1,
                label=f"{kind}.bsdf",
            )  # fmt: skip
        ax.set_theta_zero_location("N")
        ax.set_theta_direction(-1)
        ax.set_thetamin(-90)
        ax.set_thetamax(90)
        decades = np.arange(np.ceil(floor), np.floor(np.max(high)) + 1.0)
        decades = decades[:: max(1, int(np.ceil(decades.size / 3)))]  # at most 3 labels
        ax.set_yticks(decades - floor)
        ax.set_yticklabels([f"1e{d:.0f}" for d in decades], fontsize=7)
        ax.set_ylim(0.0, np.max(high) - floor + 0.2)
        ax.set_title(f"θi = {theta_i:g}°", fontsize=10)
    handles, labels = axes[0].get_legend_handles_labels()
    figure.legend(handles, labels, loc="lower center", ncol=min(len(labels), 5), fontsize=8)
    figure.suptitle(
        "In-plane cut; angle: θs [deg] from the normal (forward scatter to the right); "
        "radius: BRDF [sr⁻¹], logarithmic",
        fontsize=9,
    )
    figure.tight_layout(rect=(0, 0.08, 1, 0.95))
    return figure


def abg_table(rows: list[dict]) -> str:
    """The ABg rows (with 95 % intervals where the export was over posterior draws)."""

    def cell(row: dict, name: str, fmt: str) -> str:
        value = format(row[name], fmt)
        if f"{name}_lo95" in row:
            low, high = (format(row[f"{name}_{s}"], fmt) for s in ("lo95", "hi95"))
            return f"{value} ({low}–{high})"
        return value

    return _html.table(
        ["θi [deg]", "A [sr⁻¹]", "B [-]", "g [-]", "TIS [%]", "rms ln error [-]"],
        [
            [
                f"{row['theta_i_deg']:g}",
                cell(row, "A", ".3g"),
                cell(row, "B", ".3g"),
                cell(row, "g", ".3g"),
                f"{100 * row['tis_model']:.3f}",
                cell(row, "rms_log_error", ".3f"),
            ]
            for row in rows
        ],
    )


def export_section(exports: list[dict], figure: list[str]) -> list[str]:
    """The Export section: where the files are, the table plot (``figure``: its HTML, if
    drawn) and the ABg table."""
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
        if any(f["kind"] == "tis_q975" for f in entry["files"]):
            parts.append(f"<p>{_html.escape(_MEANINGS)}.</p>")
        if entry["format"] == "abg" and entry.get("rows"):
            parts.append(abg_table(entry["rows"]))
    return parts + figure
