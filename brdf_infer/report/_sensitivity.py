"""Figure and report section of the error-model sensitivity study (``sensitivity.json``), and
the folder the figure is written to with the result."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from brdf_infer.report import _html
from brdf_infer.runs.folder import SENSITIVITY_FIGURE, SENSITIVITY_FILE, RunFolder
from brdf_infer.scene import TIS_ANGLE_DEG
from brdf_infer.studies.sensitivity import SensitivityResult
from brdf_infer.verdict import PARETO_K_LIMIT, limit_text

PRIOR_SENSITIVITY_LIMIT = 0.05  # power-scaling sensitivity above which a component matters


def _entries(payload: dict[str, Any]) -> list[dict[str, Any]]:
    return [payload["baseline"], *payload["variants"]]


def _at(band: dict[str, list[float]], key: str, angle: float = TIS_ANGLE_DEG) -> float:
    return band[key][band["theta_i_deg"].index(angle)]


def sensitivity_figure(payload: dict[str, Any], dpi: int = 90) -> bytes:
    """PNG: TIS(70°) median and 95 % interval per variant (left) and its Δelpd ± se against
    the baseline (right), the baseline on top."""
    entries = _entries(payload)
    figure = Figure(figsize=(10.0, 0.45 * len(entries) + 1.6))
    left, right = figure.subplots(1, 2, sharey=True, gridspec_kw={"width_ratios": [3, 2]})
    positions = np.arange(len(entries))[::-1]
    median = np.array([100 * _at(e["tis"], "median") for e in entries])
    low = np.array([100 * _at(e["tis"], "lo95") for e in entries])
    high = np.array([100 * _at(e["tis"], "hi95") for e in entries])
    colours = ["C3"] + ["C0"] * (len(entries) - 1)
    for y, m, lo, hi, colour in zip(positions, median, low, high, colours, strict=True):
        left.errorbar(m, y, xerr=[[m - lo], [hi - m]], fmt="o", color=colour, capsize=3)
    left.axvspan(low[0], high[0], color="C3", alpha=0.08)
    left.set_yticks(positions, [e["name"] for e in entries])
    left.set_xlabel("TIS(70°) [%], median and 95 % interval")
    left.grid(alpha=0.3)
    d_elpd = np.array([e["d_elpd"] for e in entries])
    dse = np.array([e["dse"] for e in entries])
    right.errorbar(d_elpd, positions, xerr=dse, fmt="o", color="k", capsize=3)
    right.axvline(0.0, color="C3", lw=1)
    right.set_xlabel("Δelpd_loo vs the default ± se")
    right.grid(alpha=0.3)
    figure.tight_layout()
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=dpi)
    return buffer.getvalue()


def _interval(values: dict[str, float], scale: float = 100.0) -> str:
    return (
        f"{scale * values['median']:.2f} ({scale * values['lo95']:.2f}–"
        f"{scale * values['hi95']:.2f})"
    )


def sensitivity_rows(payload: dict[str, Any]) -> list[list[str]]:
    """One table row per posterior: name, TIS(70°), π·BRDF0 [%], Δelpd ± se, sampler health."""
    rows = []
    for entry in _entries(payload):
        tis = {key: _at(entry["tis"], key) for key in ("median", "lo95", "hi95")}
        health = entry.get("diagnostics", {})
        notes = []
        if health.get("divergences"):
            notes.append(f"{health['divergences']} divergences")
        if health.get("r_hat_max", 1.0) > 1.01:
            notes.append(f"R-hat {health['r_hat_max']:.3f}")
        if health.get("ess_bulk_min", np.inf) < 400:
            notes.append(f"ESS {health['ess_bulk_min']:.0f}")
        refitted = health.get("refitted_rows", [])
        limit = health.get("pareto_k_limit", PARETO_K_LIMIT)
        if refitted:
            notes.append(
                f"rows {', '.join(str(r + 1) for r in refitted)} refitted (k > {limit_text(limit)})"
            )
        elif health.get("pareto_k_max", 0.0) > limit:
            notes.append(f"Pareto k {health['pareto_k_max']:.2f}")
        rows.append(
            [
                entry["name"],
                _interval(tis),
                _interval(entry["pi_brdf0"]),
                f"{entry['elpd_loo']:.1f}",
                "0"
                if entry is payload["baseline"]
                else f"{entry['d_elpd']:+.1f} ± {entry['dse']:.1f}",
                "; ".join(notes) or "ok",
            ]
        )
    return rows


SENSITIVITY_HEADERS = [
    "error model",
    "TIS(70°) [%] (95 %)",
    "π·BRDF0 [%] (95 %)",
    "elpd_loo",
    "Δelpd ± se",
    "sampler, LOO",
]


def power_scaling_rows(payload: dict[str, Any]) -> list[list[str]]:
    """Prior and likelihood power-scaling sensitivity per quantity (where computed)."""
    scaling = payload.get("power_scaling") or {}
    return [
        [name, f"{values['prior']:.3f}", f"{values['likelihood']:.3f}", values["diagnosis"]]
        for name, values in scaling.items()
    ]


def sensitivity_section(run: RunFolder) -> list[str]:
    """The report's section from ``run/sensitivity.json`` (none when the run has none)."""
    payload = run.sensitivity()
    if payload is None:
        return []
    parts = [
        "<h2>Sensitivity to the error-model assumptions</h2>",
        "<p>The posterior under the scene's error model (default) and with one assumption "
        "changed at a time, each sampled with the same NUTS settings and seed: what each "
        "assumption does to the answer (TIS at 70° and π·BRDF0, median and 95 % interval), and "
        "what the data say about it (PSIS-LOO difference to the default ± its standard error; "
        "higher is better, clear when several times its se). TIS at every reported angle: "
        "<code>sensitivity.json</code>.</p>",
        _html.table(SENSITIVITY_HEADERS, sensitivity_rows(payload)),
        _html.figure(
            sensitivity_figure(payload),
            "TIS(70°) under each error-model variant (red: the default and its 95 % interval) "
            "and the variant's Δelpd_loo against the default.",
        ),
    ]
    rows = power_scaling_rows(payload)
    if rows:
        parts += [
            "<h3>Prior and likelihood sensitivity (power scaling)</h3>",
            f"<p>How much the default posterior moves when the prior or the likelihood is "
            f"raised to a power near 1 (Kallioinen et al. 2023, ArviZ <code>psens</code>; "
            f"cumulative Jensen–Shannon distance). Above {PRIOR_SENSITIVITY_LIMIT} for the "
            f"prior and the likelihood: a possible prior–data conflict; for the prior but not "
            f"the likelihood: the prior dominates a weak likelihood.</p>",
            _html.table(["quantity", "prior", "likelihood", "diagnosis"], rows),
        ]
    return parts


def write_sensitivity(out: Path, result: SensitivityResult) -> list[Path]:
    """sensitivity.json and its figure (TIS(70°) and Δelpd per variant) into ``out``,
    atomically."""
    folder, payload = RunFolder(out), result.as_json()
    return [
        folder.write_json(SENSITIVITY_FILE, payload),
        folder.write_bytes(SENSITIVITY_FIGURE, sensitivity_figure(payload)),
    ]
