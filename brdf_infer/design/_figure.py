"""The design map: expected sd ratio of the target over (θi, θs), measured rows and chosen
settings marked (plots read ``design.json``; they compute nothing)."""

from __future__ import annotations

import io
from typing import Any

import numpy as np
from matplotlib.figure import Figure


def design_figure(payload: dict[str, Any], dpi: int = 90) -> bytes:
    """PNG of the expected sd ratio after one more row at each in-plane candidate (colour),
    the measured rows (grey markers, one shape per series) and the K chosen settings
    (numbered stars)."""
    candidates = [c for c in payload["candidates"] if c["phi_s_deg"] in (0.0, 180.0)]
    figure = Figure(figsize=(7.5, 5.2))
    axes = figure.subplots()
    theta_i = np.array([c["theta_i_deg"] for c in candidates])
    theta_s = np.array([c["theta_s_deg"] for c in candidates])
    ratio = np.array([c["sd_ratio"] for c in candidates])
    if len(candidates):
        colour = axes.scatter(
            theta_i, theta_s, c=ratio, cmap="viridis_r", marker="s", s=42, edgecolors="none"
        )
        what = "geometric-mean sd ratio" if payload["target"] == "all" else "sd ratio"
        figure.colorbar(colour, ax=axes, label=f"expected {what} after one row [-]")
    markers = ["o", "^", "D", "v", "P", "X"]
    series = list(dict.fromkeys(m["series"] for m in payload["measured"]))
    for k, name in enumerate(series):
        rows = [m for m in payload["measured"] if m["series"] == name]
        axes.scatter(
            [m["theta_i_deg"] for m in rows],
            [m["theta_s_deg"] for m in rows],
            marker=markers[k % len(markers)],
            facecolors="none",
            edgecolors="0.35",
            s=60,
            label=f"measured, series {name}",
        )
    for entry in payload["chosen"]:
        axes.scatter(
            entry["theta_i_deg"], entry["theta_s_deg"], marker="*", s=260, color="C3", zorder=5
        )
        axes.annotate(
            str(entry["step"]),
            (entry["theta_i_deg"], entry["theta_s_deg"]),
            xytext=(6, 6),
            textcoords="offset points",
            color="C3",
            fontweight="bold",
        )
    axes.scatter([], [], marker="*", s=120, color="C3", label="chosen (order)")
    axes.plot([0, 90], [0, 90], color="0.6", lw=0.8, ls=":", label="specular θs = θi")
    axes.set_xlabel("θi [deg]")
    axes.set_ylabel("θs [deg] (signed in the plane, > 0 forward)")
    axes.set_title(f"where to measure next for {payload.get('target_label', payload['target'])}")
    axes.legend(loc="lower left", fontsize=8)
    axes.grid(alpha=0.3)
    figure.tight_layout()
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=dpi)
    return buffer.getvalue()
