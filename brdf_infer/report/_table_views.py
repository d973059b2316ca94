"""Views of a table as a scatterometer writes it: which rows are in the plane of incidence, a
panel grid that stays legible at many angles of incidence, the residuals of every row on the
hemisphere (one small polar panel per angle of incidence), and what reading the table left
out (its zero cells and dropouts, counted by :mod:`brdf_infer.tables.screening`'s rules)."""

from __future__ import annotations

from typing import Any

import matplotlib.pyplot as plt
import numpy as np

from brdf_infer.report import _html
from brdf_infer.tables.measurements import Measurements
from brdf_infer.tables.screening import DROPOUT_RULE, ZERO_RULE, dropout_words

LEAST_LIMIT = 0.05  # the residual map's colour scale spans at least ±0.05 (±5 %) [ln units]


def in_plane(rows: Measurements) -> np.ndarray:
    """True for the rows in the plane of incidence (φs 0° or 180°: a signed θs, no
    azimuth; :attr:`Measurements.out_of_plane` is its complement)."""
    return ~rows.out_of_plane


def value_label(quantity: str) -> str:
    """The axis label of a table's measured value, with its unit."""
    return "BRDF [sr⁻¹]" if quantity == "brdf" else "raw reflectance R [-]"


def value_words(quantity: str) -> str:
    """A table's measured value in words."""
    return "BRDF values" if quantity == "brdf" else "raw reflectance"


def panel_grid(count: int) -> tuple[int, int, tuple[float, float]]:
    """(lines, columns, panel size [in]) of small multiples, one per angle of incidence:
    three columns up to six panels, then four up to twenty (18 angles: 5 lines of 4, 13.6 in
    wide, shown near full size in the report's 1150-px column), then five."""
    columns = min(3, count) if count <= 6 else (4 if count <= 20 else 5)
    size = (5.0, 3.8) if count <= 6 else (3.4, 2.5)
    return int(np.ceil(count / columns)), columns, size


def ln_residual(idata) -> np.ndarray:
    """Each row's residual in ln units: ln value − the median of its posterior-predictive
    replicates (the observed and replicated ln values the run wrote). In ln units rather
    than in predictive sd: the replicates carry new calibration and sample effects shared by
    every row, whose sd (≈ 0.3) would hide a row's own misfit."""
    observed = np.asarray(idata.observed_data["obs"])
    replicated = np.asarray(idata.posterior_predictive["obs"]).reshape(-1, observed.size)
    return observed - np.median(replicated, axis=0)


def colour_limit(residual: np.ndarray) -> float:
    """The residual map's symmetric colour limit [ln units]: the 98th percentile of |r|,
    at least :data:`LEAST_LIMIT` (what lies beyond is drawn at the limit)."""
    return max(LEAST_LIMIT, float(np.quantile(np.abs(residual), 0.98)))


def polar_angles(rows: Measurements) -> tuple[np.ndarray, np.ndarray]:
    """(θ, φ) [deg] of every row on the hemisphere: an in-plane row's signed θs at φ = 180°
    (forward, θs > 0) or 0° (backward)."""
    theta = np.abs(rows.theta_s_deg)
    if rows.phi_s_deg is None:
        return theta, np.where(rows.theta_s_deg < 0.0, 0.0, 180.0)
    phi = np.where(rows.theta_s_deg < 0.0, 0.0, 180.0)
    return theta, np.where(rows.out_of_plane, rows.phi_s_deg, phi)


def _hemisphere_axis(axis, angle: float, half: bool) -> None:
    """One polar panel: radius θ 0–90° [deg]; ``half``: φ 0–180° only (a plane-symmetric
    table)."""
    if half:
        axis.set_thetamax(180.0)
    axis.set_ylim(0, 90)
    axis.set_yticks([30, 60, 90])
    axis.set_xticks(np.radians([0, 90, 180] if half else [0, 90, 180, 270]))
    axis.tick_params(labelsize=6, pad=0)
    axis.set_title(f"θi = {angle:g}°", fontsize=9, pad=4)


def residual_hemisphere(idata, rows: Measurements, table: dict[str, Any] | None) -> plt.Figure:
    """Every row's residual in ln units (:func:`ln_residual`) on a polar map of the
    hemisphere per angle of incidence (radius θ [deg], angle φ [deg], forward side at 180°),
    on one diverging colour scale (:func:`colour_limit`); the table's zero cells (grey) and
    dropouts (red crosses) that reading it left out are marked where they lie.

    Args:
        idata: the run's InferenceData (its observed and replicated data, one per row).
        rows: the run's rows, in its order.
        table: summary.json's ``"table"`` (None: a CSV); the zero cells' directions are
            ``rows.screening``'s.
    """
    residual = ln_residual(idata)
    limit = colour_limit(residual)
    theta, phi = polar_angles(rows)
    zeros = np.zeros((0, 3)) if rows.screening is None else rows.screening.zero_directions
    dropouts = [] if table is None else table["dropouts"]
    half = bool(np.all(phi <= 180.0) and np.all(zeros[:, 2] <= 180.0))
    angles = np.unique(rows.theta_i_deg)
    lines, columns, _ = panel_grid(len(angles))
    figure, axes = plt.subplots(
        lines,
        columns,
        figsize=(3.0 * columns + 1.2, (1.9 if half else 3.0) * lines + 0.9),
        subplot_kw={"projection": "polar"},
        squeeze=False,
        layout="constrained",
    )
    for axis, angle in zip(axes.ravel(), angles, strict=False):
        here = rows.theta_i_deg == angle
        mesh = axis.scatter(
            np.radians(phi[here]),
            theta[here],
            c=np.clip(residual[here], -limit, limit),
            cmap="RdBu_r",
            vmin=-limit,
            vmax=limit,
            s=16,
            edgecolors="0.6",
            linewidths=0.3,
        )
        _left_out(
            axis, zeros[zeros[:, 0] == angle], [d for d in dropouts if d["theta_i_deg"] == angle]
        )
        _hemisphere_axis(axis, angle, half)
    for axis in axes.ravel()[len(angles) :]:
        axis.set_visible(False)
    figure.colorbar(
        mesh,
        ax=axes.ravel().tolist(),
        shrink=0.7,
        label="residual: ln value − posterior-predictive median [ln units; 0.1 ≈ 10 %]",
    )
    figure.suptitle(
        "Residuals on the hemisphere: radius θ [deg], angle φ [deg] (forward side at 180°); "
        "grey squares: zero cells, red crosses: dropouts (both left out)",
        fontsize=10,
    )
    return figure


def _left_out(axis, zeros: np.ndarray, dropouts: list[dict[str, float]]) -> None:
    """Mark one panel's zero cells ((θi, θ, φ) [deg], grey squares) and dropouts (red
    crosses)."""
    axis.plot(np.radians(zeros[:, 2]), zeros[:, 1], "s", color="0.35", ms=4)
    phi = [d.get("phi_s_deg", 0.0 if d["theta_s_deg"] < 0 else 180.0) for d in dropouts]
    theta = [abs(d["theta_s_deg"]) for d in dropouts]
    axis.plot(np.radians(phi), theta, "x", color="crimson", ms=8, mew=2)


def table_section(summary: dict[str, Any]) -> list[str]:
    """What reading the run's .BSDF table left out, rule by rule with its count, and every
    dropout (summary.json's ``"table"``); nothing for a CSV."""
    table = summary.get("table")
    if table is None:
        return []
    rules = [
        ["zero cells", table.get("zero_rule", ZERO_RULE), str(table["zero_cells"])],
        ["dropouts", table.get("dropout_rule", DROPOUT_RULE), str(len(table["dropouts"]))],
        [
            "positive cells below the horizon",
            "not a BRDF there: left out",
            str(table.get("below_horizon", 0)),
        ],
    ]
    named = "; ".join(map(dropout_words, table["dropouts"]))
    return [
        "<h3>What reading the table left out</h3>",
        "<p>The table's smallest positive value, its detection limit: "
        f"{table['detection_limit']:.3g} sr⁻¹. Each rule and the cells it left out:</p>",
        _html.table(["cells", "rule", "left out"], rules),
        f"<p>Dropouts: {_html.escape(named)}.</p>" if named else "",
    ]
