"""Figures of the diagnostic report; each returns a matplotlib Figure with units on every axis,
laid out by fixed margins (:mod:`brdf_infer.report._canvas`)."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import matplotlib
import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.colors import BoundaryNorm, ListedColormap, LogNorm, Normalize
from matplotlib.figure import Figure

from brdf_infer._internal import arviz as az
from brdf_infer.model import ModelFamily, brdf_inplane
from brdf_infer.model.params import PARAMETER_SETS
from brdf_infer.report._canvas import Margins, colour_bar_axis, panels
from brdf_infer.report._table_views import in_plane, panel_grid, value_label
from brdf_infer.runs.records import Bands
from brdf_infer.scene import Scene
from brdf_infer.verdict import PARETO_K_LIMIT, limit_text

MAP_THETA_I_DEG = (5.0, 30.0, 50.0, 70.0)
MAX_LEGEND_ANGLES = 8  # the predictive figure's legend; a colour bar beyond


def posterior_predictive(idata: az.InferenceData, rows) -> Figure:
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
    bars = any(  # colour bars right of their panels: room for their tick labels and label
        len(np.unique(theta_i[(rows.series == name) & plane])) > MAX_LEGEND_ANGLES for name in names
    )
    margins = Margins(left=0.75, right=0.1 + 0.9 * bars, bottom=0.5, top=0.3, across=0.85 + bars)
    figure, axes = panels(((5.5 + 1.5 * bars) * len(names), 4.2), 1, len(names), margins)
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


_ANGLE_COLOURS = ListedColormap(matplotlib.colormaps["viridis"](np.linspace(0.0, 0.9, 256)))


def _angle_key(figure, axis, angles: np.ndarray) -> None:
    """Which colour is which θi: a legend up to eight angles, else a colour bar (its ticks the
    angles, one colour step each)."""
    if len(angles) <= MAX_LEGEND_ANGLES:
        axis.legend(fontsize=8)
        return
    steps = BoundaryNorm(np.arange(len(angles) + 1) - 0.5, len(angles))
    colours = ListedColormap(_ANGLE_COLOURS(np.linspace(0.0, 1.0, len(angles))))
    bar = figure.colorbar(
        ScalarMappable(norm=steps, cmap=colours), ax=axis, label="incidence angle θi [deg]"
    )
    bar.set_ticks(np.arange(len(angles)), labels=[f"{a:g}" for a in angles])
    bar.ax.tick_params(labelsize=7)


def pareto_k(loo: dict) -> Figure:
    """Every row's Pareto k of a run's PSIS-LOO (``summary.json``'s ``predictive``)."""
    figure, axes = panels((7, 3.6), margins=Margins(left=0.7, bottom=0.5, top=0.3))
    axis = axes[0, 0]
    k = np.asarray(loo["pareto_k"])
    limit = loo.get("pareto_k_limit", PARETO_K_LIMIT)
    axis.scatter(np.arange(k.size), k, s=14, c=np.where(k > limit, "crimson", "tab:blue"))
    axis.axhline(limit, color="crimson", ls=":", label=f"k = {limit_text(limit)}")
    axis.set_xlabel("measurement row [-]")
    axis.set_ylabel("Pareto k [-]")
    axis.set_title(f"PSIS-LOO: elpd = {loo['elpd_loo']:.1f} ± {loo['se']:.1f}")
    axis.legend()
    return figure


def brdf_bands(bands: Bands, scene: Scene, rows) -> Figure:
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
    margins = (  # small multiples share their axes: labels on the outer panels only
        Margins(left=1.0, right=0.15, bottom=0.5, top=0.75, across=0.15, between=0.3)
        if many
        else Margins(left=1.0, right=0.15, bottom=0.5, top=0.3, across=1.05, between=0.75)
    )
    figure, axes = panels(
        (width * columns, height * lines + 0.6 * many),
        lines,
        columns,
        margins,
        sharex=many,
        sharey=many,
    )
    reference = scene.outputs.reference_params
    if reference is not None:  # every angle's curve at once: Eq. (7) traced once, not per angle
        curves = np.asarray(
            jax.jit(brdf_inplane, static_argnums=3)(
                np.asarray(angles, float)[:, None],
                theta_s,
                PARAMETER_SETS[reference],
                scene.outputs.fold,
            )
        )
    for index, angle in enumerate(angles):
        axis = axes.ravel()[index]
        _band(axis, theta_s, band, index)
        if reference is not None:
            axis.plot(theta_s, curves[index], "k--", lw=1, label=f"reference ({reference})")
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
        figure.legend(handles, labels, loc="upper center", ncols=len(labels), fontsize=8)
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


def tis_band(bands: Bands, reference: list[tuple[float, float, str]] = ()) -> Figure:
    """TIS median and bands against θi, with the scene's reference points (e.g. Table 3)."""
    band = bands["tis"]
    theta = np.asarray(band["theta_i_deg"])
    figure, axes = panels((7, 4.2), margins=Margins(left=0.7, bottom=0.5, top=0.3))
    axis = axes[0, 0]
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
    return figure


class HemisphereMaps(NamedTuple):
    """Per angle of :data:`MAP_THETA_I_DEG`, on a grid of θ [deg] × φ [deg] (46 × 91 points):
    the posterior median BRDF [sr⁻¹] and the relative width of its 95 % band [-]."""

    theta_deg: np.ndarray
    phi_deg: np.ndarray
    medians: list[np.ndarray]
    widths: list[np.ndarray]


def hemisphere_values(member: ModelFamily, physical: dict, draws: int = 400) -> HemisphereMaps:
    """The hemisphere maps' values: the BRDF of ``member`` at ``draws`` draws (evenly spread)
    of its physical parameters in ``physical``. JAX and NumPy do the work, the GIL released:
    the report computes them in a thread while it draws other figures."""
    count = np.size(next(iter(physical.values())))
    take = np.linspace(0, count - 1, min(draws, count)).astype(int)
    batch = {name: np.asarray(v)[take][:, None, None] for name, v in physical.items()}
    theta = np.linspace(0.0, 89.0, 46)
    phi = np.linspace(0.0, 360.0, 91)
    grid_theta, grid_phi = np.meshgrid(theta, phi, indexing="ij")
    brdf = jax.jit(lambda *args: jnp.exp(member.log_brdf(*args)))  # XLA's exp: 4× NumPy's
    values = [brdf(angle, grid_theta[None], grid_phi[None], batch) for angle in MAP_THETA_I_DEG]
    medians, widths = [], []
    for value in values:  # every angle dispatched: JAX computes the next while NumPy sorts one
        low, median, high = np.quantile(np.asarray(value), [0.025, 0.5, 0.975], axis=0)
        medians.append(median)
        widths.append((high - low) / median)
    return HemisphereMaps(grid_theta, grid_phi, medians, widths)


def hemisphere_maps(
    member: ModelFamily, physical: dict, draws: int = 400, maps: HemisphereMaps | None = None
) -> Figure:
    """Polar maps (Fig. 9 convention) of the posterior median BRDF of ``member`` (every draw of
    its physical parameters in ``physical``) on one shared logarithmic colour scale, and of the
    relative width of its 95 % band on one shared linear scale; ``maps``: their values
    (:func:`hemisphere_values`), when computed already."""
    maps = hemisphere_values(member, physical, draws) if maps is None else maps
    medians, widths = maps.medians, maps.widths
    floor = max(
        min(float(np.min(m)) for m in medians), 1e-6 * max(float(np.max(m)) for m in medians)
    )
    norms = (
        LogNorm(vmin=floor, vmax=max(float(np.max(m)) for m in medians)),
        Normalize(vmin=0.0, vmax=max(float(np.max(w)) for w in widths)),
    )
    labels = ("BRDF [sr⁻¹], posterior median", "95 % band width / median [-]")
    margins = Margins(left=0.45, right=1.9, bottom=0.3, top=0.85, across=0.75, between=0.55)
    figure, axes = panels((15, 7.6), 2, 4, margins, subplot_kw={"projection": "polar"})
    for row, (values, norm, label, cmap) in enumerate(
        zip((medians, widths), norms, labels, ("viridis", "cividis"), strict=True)
    ):
        for column, angle in enumerate(MAP_THETA_I_DEG):
            axis = axes[row, column]
            mesh = axis.pcolormesh(
                np.radians(maps.phi_deg),
                maps.theta_deg,
                values[column],
                shading="auto",
                cmap=cmap,
                norm=norm,
            )
            axis.set_ylim(0, 90)
            axis.set_yticks([30, 60, 90])
            axis.tick_params(labelsize=7)
            axis.set_title(f"θi = {angle:g}°" if row == 0 else "", pad=26)  # above φ = 90°
        bar_axis = colour_bar_axis(figure, axes[row, :].tolist(), gap=0.55, shrink=0.8)
        figure.colorbar(mesh, cax=bar_axis, label=label)
    model = member.title
    figure.suptitle(
        f"Full-hemisphere BRDF, {model}: radius θ [deg], angle φ [deg] "
        "(forward side at φ = 180°); one colour scale per row"
    )
    return figure
