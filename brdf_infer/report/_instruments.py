"""The report's "Instrument models" section (``instruments.json`` of a run)."""

from __future__ import annotations

from typing import Any

import matplotlib.pyplot as plt
import numpy as np

from brdf_infer.report import _html
from brdf_infer.report._raytrace import figure_png
from brdf_infer.runs.folder import RunFolder

MEANINGS = {
    "point": "Eq. (6) at the nominal angles (the article's conversion)",
    "aperture": "dPs/Pi through AD, BRDF averaged over beam footprint and AD",
    "image": "Eq. (2): scattered over reference image in the signal square",
}


def _cell(interval: dict | None, scale: float = 1.0, digits: str = ".3g") -> str:
    if interval is None:
        return "-"
    return (
        f"{scale * interval['median']:{digits}} "
        f"({scale * interval['lo95']:{digits}}–{scale * interval['hi95']:{digits}})"
    )


def instrument_table_rows(payload: dict[str, Any]) -> list[list[str]]:
    """Rows of the side-by-side table (also in docs/instruments.md): one per instrument model."""
    rows = []
    for entry in payload["models"]:
        traced = entry.get("raytrace")
        rows.append(
            [
                entry["instrument"],
                _cell(entry["brdf0"], 1.0, ".4f"),
                _cell(entry["alpha"], 1.0, ".2f"),
                _cell(entry["tis_70deg"], 100.0, ".2f"),
                _cell(entry["pi_brdf0"], 100.0, ".2f"),
                f"{entry['elpd_loo']:.1f} ± {entry['elpd_se']:.1f}",
                "-" if traced is None else f"{traced['rms_ln_image_ratio']:.3f}",
                "-" if traced is None else f"{traced['rms_ln_simulated']:.3f}",
            ]
        )
    return rows


HEADERS = [
    "instrument",
    "BRDF0 [sr⁻¹]",
    "α [-]",
    "TIS(70°) [%]",
    "π·BRDF0 [%]",
    "elpd_loo ± se",
    "RMS ln(image ratio/measured)",
    "RMS ln(dPs/Pi / measured)",
]


def plot_instrument_traces(payload: dict[str, Any]) -> plt.Figure:
    """Measured series against the ray-traced image ratio at each instrument model's
    posterior (the Fig. 14 comparison), by configuration."""
    figure, axis = plt.subplots(figsize=(9.0, 4.0), layout="constrained")
    markers = {"point": "o", "aperture": "s", "image": "^"}
    measured = None
    for offset, entry in zip((-0.2, 0.0, 0.2), payload["models"], strict=False):
        traced = entry.get("raytrace")
        if traced is None:
            continue
        rows = traced["rows"]
        x = np.arange(len(rows))
        measured = [(r["measured"], r["measured_err"]) for r in rows]
        axis.plot(
            x + offset,
            [r["image_ratio"] for r in rows],
            markers.get(entry["instrument"], "x"),
            label=f"ray traced, posterior of '{entry['instrument']}'",
        )
    if measured is not None:
        values, errors = np.array(measured).T
        axis.errorbar(
            np.arange(len(values)), values, errors, fmt="k_", ms=14, label="measured (Table 2)"
        )
        labels = [
            f"{r['theta_i_deg']:g}/{r['delta_deg']:+g}"
            for r in payload["models"][0]["raytrace"]["rows"]
        ]
        axis.set_xticks(np.arange(len(labels)), labels, rotation=60, fontsize=8)
    axis.set_yscale("log")
    axis.set_xlabel("configuration θi [deg] / δ [deg]")
    axis.set_ylabel("raw reflectance, Eq. (2) image ratio [-]")
    axis.legend(fontsize=8)
    return figure


def instruments_section(run: RunFolder) -> list[str]:
    """HTML of the section, empty when the run has no ``instruments.json``."""
    payload = run.instruments()
    if payload is None:
        return []
    meaning = "; ".join(
        f"<b>{name}</b>: {_html.escape(text)}"
        for name, text in MEANINGS.items()
        if any(e["instrument"] == name for e in payload["models"])
    )
    parts = [
        "<h2>Instrument models</h2>",
        f"<p>The same rows, priors and error model; only what a measured raw reflectance is "
        f"differs ({meaning}). Medians with 95 % intervals. The last two columns: the ray "
        f"tracer's series {payload['series']} at {payload['draws_traced']} draws of each "
        f"posterior against the measured values.</p>",
        _html.table(HEADERS, instrument_table_rows(payload)),
    ]
    if any(entry.get("raytrace") for entry in payload["models"]):
        parts.append(
            _html.figure(
                figure_png(plot_instrument_traces(payload)),
                "Measured raw reflectance of the ray-traced series (Table 2) and the ray "
                "tracer's Eq. (2) image ratio at each instrument model's posterior (median "
                "over the traced draws).",
            )
        )
    return parts
