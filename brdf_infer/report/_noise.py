"""Report figures of the error model: LOO-PIT of the error models side by side, and the
inter-sample spread the model predicts against the one measured."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from brdf_infer._internal import arviz as az
from brdf_infer.report._canvas import Margins, panels
from brdf_infer.studies.uniformity import ecdf_band


def loo_pit_comparison(pits: dict[str, tuple[np.ndarray, float]]) -> Figure:
    """ECDF − uniform of each error model's LOO-PIT values with a simultaneous 95 % band.

    Args:
        pits: error model name → (LOO-PIT values, KS p-value).
    """
    # one panel (5.2 in) is narrower than the title on one line: two lines then
    joint = ": " if len(pits) > 1 else ":\n"
    margins = Margins(left=0.8, right=0.15, bottom=0.5, top=0.55 + 0.25 * (len(pits) == 1))
    figure, axes = panels((5.2 * len(pits), 3.9), 1, len(pits), margins)
    grid = np.linspace(0.0, 1.0, 201)[1:-1]
    for axis, (name, (values, p_value)) in zip(axes[0], pits.items(), strict=True):
        values = np.asarray(values)
        low, high = ecdf_band(values.size, grid)
        ecdf = np.mean(values[:, None] <= grid[None, :], axis=0)
        axis.fill_between(grid, low - grid, high - grid, color="0.85", label="95 % band, uniform")
        axis.axhline(0.0, color="0.5", lw=0.8)
        axis.step(grid, ecdf - grid, where="post", color="C3", label="LOO-PIT ECDF − uniform")
        axis.set_title(f"{name}: KS p = {p_value:.2f} ({values.size} rows)")
        axis.set_xlabel("LOO-PIT value [-]")
        axis.set_ylabel("ECDF − uniform CDF [-]")
        axis.legend(fontsize=7, loc="lower right")
    figure.suptitle(f"Leave-one-out predictive calibration{joint}inside the band when calibrated")
    return figure


def spread_groups(idata: az.InferenceData) -> dict[float, np.ndarray]:
    """θi → rows of every geometry (series, θi, θs) measured on two or more samples."""
    data = idata.constant_data
    theta_i = np.asarray(data["theta_i_deg"])
    theta_s = np.asarray(data["theta_s_deg"])
    samples = np.asarray(data["sample_index"])
    series = np.asarray(data["series_index"])
    groups: dict[float, np.ndarray] = {}
    for key in dict.fromkeys(zip(series, theta_i, theta_s, strict=True)):
        rows = np.flatnonzero((series == key[0]) & (theta_i == key[1]) & (theta_s == key[2]))
        if len(set(samples[rows])) >= 2:
            groups[float(key[1])] = rows
    return groups


def spread_check(idata: az.InferenceData) -> Figure | None:
    """Observed sd of ln R over samples per θi against its posterior predictive distribution
    and the fitted sample-to-sample scale τ; None without geometries measured on two samples."""
    groups = spread_groups(idata)
    if not groups:
        return None
    observed = np.asarray(idata.observed_data["obs"])
    replicated = np.asarray(idata.posterior_predictive["obs"])
    replicated = replicated.reshape(-1, replicated.shape[-1])
    angles = sorted(groups)
    figure, axes = panels((7, 4.2), margins=Margins(left=0.75, bottom=0.5, top=0.3))
    axis = axes[0, 0]
    for position, angle in enumerate(angles):
        rows = groups[angle]
        predicted = np.std(replicated[:, rows], axis=1, ddof=1)
        low, median, high = np.quantile(predicted, [0.025, 0.5, 0.975])
        axis.vlines(
            angle,
            low,
            high,
            color="C0",
            lw=6,
            alpha=0.45,
            label="posterior predictive 95 %" if position == 0 else None,
        )
        axis.plot(angle, median, "_", color="C0", ms=14)
        axis.plot(
            angle,
            np.std(observed[rows], ddof=1),
            "o",
            color="k",
            label="measured" if position == 0 else None,
        )
    if "sample_sd" in idata.posterior:
        tau = np.asarray(idata.posterior["sample_sd"]).ravel()
        low, median, high = np.quantile(tau, [0.025, 0.5, 0.975])
        axis.axhspan(low, high, color="C2", alpha=0.15, label="sample-to-sample τ, 95 %")
        axis.axhline(median, color="C2", lw=1)
    axis.set_xlabel("incidence angle θi [deg]")
    axis.set_ylabel("sd of ln R over samples [-]")
    axis.set_title("Inter-sample spread: measured against the error model")
    axis.set_ylim(bottom=0)
    axis.legend(fontsize=8)
    return figure
