"""Figures of the diagnostic report; each returns a matplotlib Figure with units on every axis."""

from __future__ import annotations

import json

import jax
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import BoundaryNorm, ListedColormap

from brdf_infer._internal import arviz as az
from brdf_infer.model import ModelFamily, brdf_inplane, family, run_family_name
from brdf_infer.model.params import PARAM_NAMES, PARAMETER_SETS
from brdf_infer.report._table_views import in_plane, panel_grid, value_label
from brdf_infer.runs.records import Bands
from brdf_infer.scene import Scene
from brdf_infer.verdict import PARETO_K_LIMIT, limit_text

MAP_THETA_I_DEG = (5.0, 30.0, 50.0, 70.0)


# The sampler's well-conditioned coordinates (brdf_infer.model.coordinates) and noise scales, with
# their units: what the trace and pair plots show (in paper units a2, a3 are spikes).
SAMPLER_COORDINATES = {
    "log_brdf0": "ln BRDF0 [ln sr⁻¹]",
    "b1": "b1 = a1·90² [-]",
    "b2": "b2 = a2·90^(1+α) [-]",
    "b3": "b3 = a3·90^(2+α) [-]",
    "alpha": "α [-]",
    "theta_s0": "θs0 [deg]",
    "sample_sd": "sample sd τ [ln R]",
    "repeatability": "repeatability [ln R]",
}
_PAPER_NAME = {"log_brdf0": "brdf0", "b1": "a1", "b2": "a2", "b3": "a3"}


SHORT_NAMES = {
    "log_brdf0": "ln BRDF0",
    "b1": "b1",
    "b2": "b2",
    "b3": "b3",
    "alpha": "α",
    "theta_s0": "θs0 [deg]",
    "sample_sd": "τ",
    "repeatability": "σ_rep",
}
COORDINATE_NOTE = (
    "ln BRDF0 [ln sr⁻¹]; b1 = a1·90², b2 = a2·90^(1+α), b3 = a3·90^(2+α) [-]; α [-]; θs0 [deg]; "
    "sample sd τ and repeatability σ_rep [ln R]"
)


def _family(idata: az.InferenceData) -> ModelFamily:
    """The run's model family."""
    return family(run_family_name(idata.posterior.attrs))


def sampled_coordinates(idata: az.InferenceData) -> list[str]:
    """The run's free coordinates (also a chain that never moved is shown)."""
    member = _family(idata)
    noise = [name for name in ("sample_sd", "repeatability") if name in idata.posterior]
    if not member.paper_parameters:  # sampled in its own coordinates
        return [c.site for c in member.coordinates] + noise
    free = json.loads(idata.posterior.attrs.get("free_parameters", json.dumps(PARAM_NAMES)))
    return [
        name
        for name in SAMPLER_COORDINATES
        if name in idata.posterior and (_PAPER_NAME.get(name, name) in free or name in noise)
    ]


def coordinate_labels(idata: az.InferenceData, short: bool = False) -> dict[str, str]:
    """Axis label of each sampled coordinate (the family's descriptions for other families)."""
    member = _family(idata)
    labels = dict(SHORT_NAMES if short else SAMPLER_COORDINATES)
    if not member.paper_parameters:
        labels.update({c.site: c.site if short else c.description for c in member.coordinates})
    return labels


def coordinate_note(idata: az.InferenceData) -> str:
    """What the pair plot's coordinates are, in words with units."""
    member = _family(idata)
    if member.paper_parameters:  # its whitened coordinates
        return COORDINATE_NOTE
    return "; ".join(f"{c.site}: {c.description}" for c in member.coordinates)


def _labeller(idata: az.InferenceData, short: bool = False):
    return az.MapLabeller(var_name_map=coordinate_labels(idata, short))


def trace(idata: az.InferenceData):
    names = sampled_coordinates(idata)
    axes = az.plot_trace(
        idata,
        var_names=names,
        compact=False,
        figsize=(11, 1.6 * len(names)),
        labeller=_labeller(idata),
    )
    figure = axes.ravel()[0].figure
    for axis in axes.ravel():
        axis.tick_params(labelsize=7)
        axis.title.set_fontsize(9)
    figure.suptitle("Trace in the sampler's coordinates (left: density per chain; right: draws)")
    figure.tight_layout()
    return figure


def rank(idata: az.InferenceData):
    names = sampled_coordinates(idata)
    columns = 4
    lines = int(np.ceil(len(names) / columns))
    figure, axes = plt.subplots(lines, columns, figsize=(12, 2.8 * lines), squeeze=False)
    az.plot_rank(idata, var_names=names, ax=axes.ravel()[: len(names)], labeller=_labeller(idata))
    for axis in axes.ravel():
        axis.tick_params(labelsize=7)
        axis.title.set_fontsize(9)
        axis.xaxis.label.set_fontsize(8)
        axis.yaxis.label.set_fontsize(8)
    for axis in axes.ravel()[len(names) :]:
        axis.set_visible(False)
    figure.suptitle("Rank plots per chain (uniform when chains agree)")
    figure.tight_layout()
    return figure


def pair(idata: az.InferenceData):
    has_divergences = "diverging" in idata.sample_stats
    names = sampled_coordinates(idata)
    axes = az.plot_pair(
        idata,
        var_names=names,
        kind="scatter",
        divergences=has_divergences,
        marginals=True,
        figsize=(12, 12),
        textsize=9,
        labeller=_labeller(idata, short=True),
        scatter_kwargs={"alpha": 0.15, "s": 2},
    )
    figure = np.ravel(axes)[0].figure
    for axis in np.ravel(axes):
        axis.tick_params(labelsize=7)
    note = " (divergences in red)" if has_divergences else ""
    figure.suptitle(
        f"Pairs in the sampler's coordinates{note}:\n{coordinate_note(idata)}", fontsize=10
    )
    figure.subplots_adjust(top=0.93, left=0.07, bottom=0.06, right=0.98)
    return figure


def energy(idata: az.InferenceData):
    figure, axis = plt.subplots(figsize=(6, 4))
    az.plot_energy(idata, ax=axis)
    axis.set_title("NUTS energy: marginal vs transition (BFMI in legend)")
    axis.set_xlabel("energy − mean [-]")
    figure.tight_layout()
    return figure


def posterior_predictive(idata: az.InferenceData, rows) -> plt.Figure:
    """The measured in-plane rows (out-of-plane rows have their own view) against their 95 %
    posterior predictive, per series; colours by θi, a colour bar beyond eight angles."""
    observed = np.exp(np.asarray(idata.observed_data["obs"]))
    replicated = np.exp(np.asarray(idata.posterior_predictive["obs"]).reshape(-1, observed.size))
    low, median, high = np.quantile(replicated, [0.025, 0.5, 0.975], axis=0)
    theta_i = np.asarray(idata.constant_data["theta_i_deg"])
    theta_s = np.asarray(idata.constant_data["theta_s_deg"])
    sigma = np.asarray(idata.constant_data["sigma_row"])
    plane = in_plane(rows)
    names = list(dict.fromkeys(rows.series[plane]))
    figure, axes = plt.subplots(
        1, len(names), figsize=(5.5 * len(names), 4.2), squeeze=False, layout="constrained"
    )
    for axis, name in zip(axes[0], names, strict=True):
        shown = np.flatnonzero((rows.series == name) & plane)
        specular = np.allclose(theta_s[shown], theta_i[shown])
        x = theta_i if specular else theta_s - theta_i
        angles = np.unique(theta_i[shown])
        colours = _ANGLE_COLOURS(np.linspace(0.0, 1.0, len(angles)))
        for colour, angle in zip(colours, angles, strict=True):
            chosen = shown[theta_i[shown] == angle]
            offset = 0.6  # predictive bars beside the data points
            axis.vlines(
                x[chosen] + offset, low[chosen], high[chosen], color=colour, alpha=0.5, lw=3
            )
            axis.plot(x[chosen] + offset, median[chosen], "_", color=colour, ms=8)
            axis.errorbar(
                x[chosen],
                observed[chosen],
                yerr=observed[chosen] * sigma[chosen],  # the value's own 1σ
                fmt="o",
                color=colour,
                ms=4,
                label=f"θi = {angle:g}°",
            )
        axis.set_yscale("log")
        axis.set_xlabel("θi [deg] (specular, θs = θi)" if specular else "δ = θs − θi [deg]")
        axis.set_ylabel(value_label(rows.quantity))
        axis.set_title(f"series {name}: measured (points, 1σ), 95 % predictive (bars)")
        _angle_key(figure, axis, angles)
    return figure


_ANGLE_COLOURS = ListedColormap(plt.cm.viridis(np.linspace(0.0, 0.9, 256)))


def _angle_key(figure, axis, angles: np.ndarray) -> None:
    """Which colour is which θi: a legend up to eight angles, else a colour bar (its ticks the
    angles, one colour step each)."""
    if len(angles) <= 8:
        axis.legend(fontsize=8)
        return
    steps = BoundaryNorm(np.arange(len(angles) + 1) - 0.5, len(angles))
    colours = ListedColormap(_ANGLE_COLOURS(np.linspace(0.0, 1.0, len(angles))))
    bar = figure.colorbar(
        plt.cm.ScalarMappable(norm=steps, cmap=colours), ax=axis, label="incidence angle θi [deg]"
    )
    bar.set_ticks(np.arange(len(angles)), labels=[f"{a:g}" for a in angles])
    bar.ax.tick_params(labelsize=7)


def pareto_k(loo: dict) -> plt.Figure:
    """Every row's Pareto k of a run's PSIS-LOO (``summary.json``'s ``predictive``)."""
    figure, axis = plt.subplots(figsize=(7, 3.6))
    k = np.asarray(loo["pareto_k"])
    limit = loo.get("pareto_k_limit", PARETO_K_LIMIT)
    axis.scatter(np.arange(k.size), k, s=14, c=np.where(k > limit, "crimson", "tab:blue"))
    axis.axhline(limit, color="crimson", ls=":", label=f"k = {limit_text(limit)}")
    axis.set_xlabel("measurement row [-]")
    axis.set_ylabel("Pareto k [-]")
    axis.set_title(f"PSIS-LOO: elpd = {loo['elpd_loo']:.1f} ± {loo['se']:.1f}")
    axis.legend()
    figure.tight_layout()
    return figure


def brdf_bands(bands: Bands, scene: Scene, rows) -> plt.Figure:
    """In-plane BRDF median and bands per θi on a log axis, the in-plane rows (φs 0° or 180°;
    out-of-plane rows have their own view, ``_table_views.residual_hemisphere``) and the
    reference
    curve (Fig. 11); small multiples that stay legible at 18 angles (:func:`panel_grid`)."""
    band = bands["brdf_inplane"]
    theta_s = np.asarray(band["theta_s_deg"])
    angles = band["theta_i_deg"]
    plane = in_plane(rows)
    measured = np.exp(scene.measured_log_brdf(rows))
    lines, columns, (width, height) = panel_grid(len(angles))
    many = len(angles) > 6
    figure, axes = plt.subplots(
        lines,
        columns,
        figsize=(width * columns, height * lines + 0.6 * many),
        squeeze=False,
        sharex=many,
        sharey=many,
        layout="constrained",
    )
    for index, angle in enumerate(angles):
        axis = axes.ravel()[index]
        _band(axis, theta_s, band, index)
        reference = scene.outputs.reference_params
        if reference is not None:
            curve = brdf_inplane(angle, theta_s, PARAMETER_SETS[reference], scene.outputs.fold)
            axis.plot(theta_s, np.asarray(curve), "k--", lw=1, label=f"reference ({reference})")
        here = plane & (rows.theta_i_deg == angle)
        if here.any():
            axis.plot(
                rows.theta_s_deg[here],
                measured[here],
                "o",
                color="tab:orange",
                ms=3 if many else 4,
                label="in-plane data" + ("" if rows.quantity == "brdf" else " (Eq. 6)"),
            )
        axis.set_yscale("log")
        axis.set_xlabel("θs [deg]")
        axis.set_ylabel("BRDF [sr⁻¹]")
        axis.set_title(f"θi = {angle:g}°", fontsize=9 if many else None)
        if many:
            axis.label_outer()
            axis.tick_params(labelsize=8)
    for axis in axes.ravel()[len(angles) :]:
        axis.set_visible(False)
    for axis in axes.ravel()[max(0, len(angles) - columns) : len(angles)]:
        axis.xaxis.set_tick_params(labelbottom=True)  # the lowest panel of its column
        axis.set_xlabel("θs [deg]")
    if many:  # a legend in a small panel hides data: above the grid
        handles, labels = axes.ravel()[0].get_legend_handles_labels()
        figure.legend(handles, labels, loc="outside upper center", ncols=len(labels), fontsize=8)
    else:
        axes.ravel()[0].legend(fontsize=7)
    return figure


def _band(axis, theta_s: np.ndarray, band: dict, index: int) -> None:
    """One angle's 95 % and 68 % bands and median [sr⁻¹] against θs [deg]."""
    for low, high, alpha, label in (("lo95", "hi95", 0.2, "95 %"), ("lo68", "hi68", 0.35, "68 %")):
        axis.fill_between(
            theta_s, band[low][index], band[high][index], alpha=alpha, color="tab:blue", label=label
        )
    axis.plot(theta_s, band["median"][index], color="tab:blue", label="posterior median")


def tis_band(bands: Bands, reference: list[tuple[float, float, str]] = ()) -> plt.Figure:
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


def hemisphere_maps(member: ModelFamily, physical: dict, draws: int = 400) -> plt.Figure:
    """Polar maps (Fig. 9 convention) of the posterior median BRDF of ``member`` (every draw of
    its physical parameters in ``physical``) on one shared logarithmic colour scale, and of the
    relative width of its 95 % band on one shared linear scale."""
    from matplotlib.colors import LogNorm, Normalize

    count = np.size(next(iter(physical.values())))
    take = np.linspace(0, count - 1, min(draws, count)).astype(int)
    batch = {name: np.asarray(v)[take][:, None, None] for name, v in physical.items()}
    theta = np.linspace(0.0, 89.0, 46)
    phi = np.linspace(0.0, 360.0, 91)
    grid_theta, grid_phi = np.meshgrid(theta, phi, indexing="ij")
    medians, widths = [], []
    log_brdf = jax.jit(member.log_brdf)
    for angle in MAP_THETA_I_DEG:
        values = np.exp(np.asarray(log_brdf(angle, grid_theta[None], grid_phi[None], batch)))
        low, median, high = np.quantile(values, [0.025, 0.5, 0.975], axis=0)
        medians.append(median)
        widths.append((high - low) / median)
    floor = max(
        min(float(np.min(m)) for m in medians), 1e-6 * max(float(np.max(m)) for m in medians)
    )
    norms = (
        LogNorm(vmin=floor, vmax=max(float(np.max(m)) for m in medians)),
        Normalize(vmin=0.0, vmax=max(float(np.max(w)) for w in widths)),
    )
    labels = ("BRDF [sr⁻¹], posterior median", "95 % band width / median [-]")
    figure, axes = plt.subplots(
        2, 4, figsize=(15, 7.6), subplot_kw={"projection": "polar"}, layout="constrained"
    )
    for row, (maps, norm, label, cmap) in enumerate(
        zip((medians, widths), norms, labels, ("viridis", "cividis"), strict=True)
    ):
        for column, angle in enumerate(MAP_THETA_I_DEG):
            axis = axes[row, column]
            mesh = axis.pcolormesh(
                np.radians(grid_phi), grid_theta, maps[column], shading="auto", cmap=cmap, norm=norm
            )
            axis.set_ylim(0, 90)
            axis.set_yticks([30, 60, 90])
            axis.tick_params(labelsize=7)
            axis.set_title(f"θi = {angle:g}°" if row == 0 else "", pad=10)
        figure.colorbar(mesh, ax=axes[row, :].tolist(), shrink=0.8, label=label)
    model = member.title
    figure.suptitle(
        f"Full-hemisphere BRDF, {model}: radius θ [deg], angle φ [deg] "
        "(forward side at φ = 180°); one colour scale per row"
    )
    return figure
