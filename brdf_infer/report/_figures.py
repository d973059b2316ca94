"""Figures of the diagnostic report; each returns a matplotlib Figure with units on every axis."""

from __future__ import annotations

import json

import matplotlib

from brdf_infer._arviz import az

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from brdf_infer.model import brdf_hemisphere, brdf_inplane, reflectance_to_brdf
from brdf_infer.params import PARAM_NAMES, PARAMETER_SETS, HemisphereConstants, Params
from brdf_infer.scene import Scene

MAP_THETA_I_DEG = (5.0, 30.0, 50.0, 70.0)


def _sampled(idata: az.InferenceData) -> list[str]:
    """The free parameters of the run (also a chain that never moved is shown)."""
    free = json.loads(idata.posterior.attrs.get("free_parameters", json.dumps(PARAM_NAMES)))
    return [n for n in PARAM_NAMES if n in free]


def trace(idata: az.InferenceData):
    axes = az.plot_trace(idata, var_names=_sampled(idata), compact=False, figsize=(10, 11))
    figure = axes.ravel()[0].figure
    figure.suptitle(
        "Trace (paper units: brdf0 sr⁻¹, a1 deg⁻², a2 deg^(−1−α), a3 deg^(−2−α), θs0 deg)"
    )
    figure.tight_layout()
    return figure


def rank(idata: az.InferenceData):
    names = _sampled(idata)
    figure, axes = plt.subplots(2, 3, figsize=(11, 6))
    az.plot_rank(idata, var_names=names, ax=axes.ravel()[: len(names)])
    for axis in axes.ravel()[len(names) :]:
        axis.set_visible(False)
    figure.suptitle("Rank plots per chain (uniform when chains agree)")
    figure.tight_layout()
    return figure


def pair(idata: az.InferenceData):
    has_divergences = "diverging" in idata.sample_stats
    axes = az.plot_pair(
        idata,
        var_names=_sampled(idata),
        kind="scatter",
        divergences=has_divergences,
        marginals=True,
        figsize=(11, 11),
        scatter_kwargs={"alpha": 0.15, "s": 2},
    )
    figure = np.ravel(axes)[0].figure
    note = " (divergences in red)" if has_divergences else ""
    figure.suptitle(f"Pairs of the parameters, paper units{note}")
    return figure


def energy(idata: az.InferenceData):
    figure, axis = plt.subplots(figsize=(6, 4))
    az.plot_energy(idata, ax=axis)
    axis.set_title("NUTS energy: marginal vs transition (BFMI in legend)")
    axis.set_xlabel("energy − mean [-]")
    figure.tight_layout()
    return figure


def posterior_predictive(idata: az.InferenceData, series: np.ndarray):
    """Measured raw reflectance against the 95 % posterior predictive, per series."""
    observed = np.exp(np.asarray(idata.observed_data["obs"]))
    replicated = np.exp(np.asarray(idata.posterior_predictive["obs"]).reshape(-1, observed.size))
    low, median, high = np.quantile(replicated, [0.025, 0.5, 0.975], axis=0)
    theta_i = np.asarray(idata.constant_data["theta_i_deg"])
    theta_s = np.asarray(idata.constant_data["theta_s_deg"])
    sigma = np.asarray(idata.constant_data["sigma_row"])
    names = list(dict.fromkeys(series))
    figure, axes = plt.subplots(1, len(names), figsize=(5.5 * len(names), 4.2), squeeze=False)
    for axis, name in zip(axes[0], names, strict=True):
        rows = np.flatnonzero(series == name)
        specular = np.allclose(theta_s[rows], theta_i[rows])
        x = theta_i[rows] if specular else theta_s[rows] - theta_i[rows]
        colours = plt.cm.viridis(np.linspace(0, 0.9, len(np.unique(theta_i[rows]))))
        for colour, angle in zip(colours, np.unique(theta_i[rows]), strict=True):
            chosen = rows[theta_i[rows] == angle]
            xs = x[np.isin(rows, chosen)]
            offset = 0.6  # predictive bars beside the data points
            axis.vlines(xs + offset, low[chosen], high[chosen], color=colour, alpha=0.5, lw=3)
            axis.plot(xs + offset, median[chosen], "_", color=colour, ms=8)
            axis.errorbar(
                xs,
                observed[chosen],
                yerr=observed[chosen] * sigma[chosen],  # the value's own 1σ
                fmt="o",
                color=colour,
                ms=4,
                label=f"θi = {angle:g}°",
            )
        axis.set_yscale("log")
        axis.set_xlabel("θi [deg] (specular, θs = θi)" if specular else "δ = θs − θi [deg]")
        axis.set_ylabel("raw reflectance R [-]")
        axis.set_title(f"series {name}: measured (points, 1σ), 95 % predictive (bars)")
        axis.legend(fontsize=8)
    figure.tight_layout()
    return figure


def pareto_k(loo) -> plt.Figure:
    figure, axis = plt.subplots(figsize=(7, 3.6))
    k = np.asarray(loo.pareto_k)
    axis.scatter(np.arange(k.size), k, s=14, c=np.where(k > 0.7, "crimson", "tab:blue"))
    axis.axhline(0.7, color="crimson", ls=":", label="k = 0.7")
    axis.set_xlabel("measurement row [-]")
    axis.set_ylabel("Pareto k [-]")
    axis.set_title(f"PSIS-LOO: elpd = {loo.elpd_loo:.1f} ± {loo.se:.1f}")
    axis.legend()
    figure.tight_layout()
    return figure


def brdf_bands(bands: dict, scene: Scene, rows) -> plt.Figure:
    """In-plane BRDF median and bands per θi on a log axis, data and paper curve (Fig. 11)."""
    band = bands["brdf_inplane"]
    theta_s = np.asarray(band["theta_s_deg"])
    angles = band["theta_i_deg"]
    d, r = scene.apertures(rows)
    measured = np.asarray(reflectance_to_brdf(rows.reflectance, rows.theta_s_deg, d, r))
    columns = min(3, len(angles))
    lines = int(np.ceil(len(angles) / columns))
    figure, axes = plt.subplots(lines, columns, figsize=(5 * columns, 3.8 * lines), squeeze=False)
    for index, angle in enumerate(angles):
        axis = axes.ravel()[index]
        axis.fill_between(
            theta_s,
            band["lo95"][index],
            band["hi95"][index],
            alpha=0.2,
            color="tab:blue",
            label="95 %",
        )
        axis.fill_between(
            theta_s,
            band["lo68"][index],
            band["hi68"][index],
            alpha=0.35,
            color="tab:blue",
            label="68 %",
        )
        axis.plot(theta_s, band["median"][index], color="tab:blue", label="posterior median")
        reference = scene.outputs.reference_params
        if reference is not None:
            curve = brdf_inplane(angle, theta_s, PARAMETER_SETS[reference], scene.model.fold)
            axis.plot(theta_s, np.asarray(curve), "k--", lw=1, label=f"paper ({reference})")
        here = rows.theta_i_deg == angle
        if here.any():
            axis.plot(
                rows.theta_s_deg[here],
                measured[here],
                "o",
                color="tab:orange",
                ms=4,
                label="data (Eq. 6)",
            )
        axis.set_yscale("log")
        axis.set_xlabel("θs [deg]")
        axis.set_ylabel("BRDF [sr⁻¹]")
        axis.set_title(f"θi = {angle:g}°")
    for axis in axes.ravel()[len(angles) :]:
        axis.set_visible(False)
    axes.ravel()[0].legend(fontsize=7)
    figure.tight_layout()
    return figure


def tis_band(bands: dict, reference: list[tuple[float, float, str]] = ()) -> plt.Figure:
    """TIS median and bands against θi, with the scene's reference points (e.g. Table 3)."""
    band = bands["tis"]
    theta = np.asarray(band["theta_i_deg"])
    figure, axis = plt.subplots(figsize=(7, 4.2))
    axis.fill_between(
        theta,
        100 * np.asarray(band["lo95"]),
        100 * np.asarray(band["hi95"]),
        alpha=0.2,
        color="tab:blue",
        label="95 %",
    )
    axis.fill_between(
        theta,
        100 * np.asarray(band["lo68"]),
        100 * np.asarray(band["hi68"]),
        alpha=0.35,
        color="tab:blue",
        label="68 %",
    )
    axis.plot(theta, 100 * np.asarray(band["median"]), color="tab:blue", label="posterior median")
    markers = iter("*sD^v")
    for label in dict.fromkeys(label for _, _, label in reference):
        points = np.array([(a, v) for a, v, name in reference if name == label])
        axis.plot(
            points[:, 0], 100 * points[:, 1], next(markers), color="k", ms=9, ls="", label=label
        )
    axis.set_xlabel("incidence angle θi [deg]")
    axis.set_ylabel("TIS [%]")
    axis.set_title("Total integrated scatter, Eq. (9)")
    axis.legend(fontsize=8)
    figure.tight_layout()
    return figure


def hemisphere_maps(params: Params, constants: HemisphereConstants, draws: int = 400) -> plt.Figure:
    """Polar maps (Fig. 9 convention) of the posterior median and relative 95 % width."""
    take = np.linspace(0, np.size(params.brdf0) - 1, min(draws, np.size(params.brdf0))).astype(int)
    batch = Params(*(np.asarray(v)[take][:, None, None] for v in params))
    theta = np.linspace(0.0, 89.0, 46)
    phi = np.linspace(0.0, 360.0, 91)
    grid_theta, grid_phi = np.meshgrid(theta, phi, indexing="ij")
    figure, axes = plt.subplots(2, 4, figsize=(16, 8), subplot_kw={"projection": "polar"})
    for column, angle in enumerate(MAP_THETA_I_DEG):
        values = np.asarray(
            brdf_hemisphere(angle, grid_theta[None], grid_phi[None], batch, True, constants)
        )
        low, median, high = np.quantile(values, [0.025, 0.5, 0.975], axis=0)
        for row, (data, label, cmap) in enumerate(
            [
                (np.log10(median), "log10 BRDF [sr⁻¹]", "magma"),
                ((high - low) / median, "95 % width / median [-]", "viridis"),
            ]
        ):
            axis = axes[row, column]
            mesh = axis.pcolormesh(
                np.radians(grid_phi), grid_theta, data, shading="auto", cmap=cmap
            )
            axis.set_ylim(0, 90)
            axis.set_yticks([30, 60, 90])
            axis.set_title(f"θi = {angle:g}°" if row == 0 else "", pad=12)
            figure.colorbar(mesh, ax=axis, shrink=0.7, label=label)
    figure.suptitle(
        "Full-hemisphere BRDF, Eqs. (8), (10): radius θ [deg], angle φ [deg] "
        "(forward side at φ = 180°)"
    )
    figure.tight_layout()
    return figure
