"""The sampler's chains drawn for the report's Diagnostics: trace, rank and pair plots of the
sampled coordinates, with matplotlib directly (the panels ArviZ's ``plot_trace``,
``plot_rank`` and ``plot_pair`` draw, at a fraction of their cost: no layout engine, one
collection per chain, only the pair plot's lower triangle created)."""

from __future__ import annotations

import json

import numpy as np
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure
from scipy.stats import rankdata

from brdf_infer._internal import arviz as az
from brdf_infer.model import ModelFamily, family, run_family_name
from brdf_infer.model.params import PARAM_NAMES
from brdf_infer.report._canvas import Margins, new_figure, panels

DENSITY_POINTS = 512  # the grid of a marginal density, as ArviZ's

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


def chain_draws(idata: az.InferenceData, name: str) -> np.ndarray:
    """(chain, draw) values of the scalar sample site ``name``."""
    values = np.asarray(idata.posterior[name])
    return values.reshape(values.shape[0], values.shape[1])


def density(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(grid, density) of ``values``: a Gaussian kernel density on :data:`DENSITY_POINTS` bins
    spanning the values, the binned counts convolved with the kernel and reflected at both
    ends (no mass beyond the draws' range), bandwidth by Silverman's rule (0.9 · min(sd,
    IQR/1.34) · n^(-1/5)); normalised to unit area."""
    low, high = float(np.min(values)), float(np.max(values))
    counts, edges = np.histogram(values, DENSITY_POINTS, (low, high))
    step = edges[1] - edges[0]
    quartiles = np.percentile(values, [25, 75])
    spread = min(float(np.std(values)), float(quartiles[1] - quartiles[0]) / 1.34)
    bandwidth = max(0.9 * spread * values.size**-0.2 / step, 0.5)  # [bins]; ≥ half a bin
    reach = min(int(np.ceil(4 * bandwidth)), DENSITY_POINTS - 1)  # [bins], as far as mirrored
    kernel = np.exp(-0.5 * (np.arange(-reach, reach + 1) / bandwidth) ** 2)
    mirrored = np.concatenate([counts[reach - 1 :: -1], counts, counts[::-1][:reach]])
    smooth = np.convolve(mirrored, kernel, mode="valid")
    return (edges[1:] + edges[:-1]) / 2, smooth / (smooth.sum() * step)


def trace(idata: az.InferenceData) -> Figure:
    """Per sampled coordinate (titled with its units): the marginal density of each chain
    (left, no density scale) and each chain's draws in order (right)."""
    names, labels = sampled_coordinates(idata), coordinate_labels(idata)
    margins = Margins(left=0.2, right=0.15, bottom=0.3, top=0.75, across=0.65, between=0.55)
    figure, axes = panels((11, 1.6 * len(names)), len(names), 2, margins)
    for (left, right), name in zip(axes, names, strict=True):
        draws = chain_draws(idata, name)
        for chain, values in enumerate(draws):
            left.plot(*density(values), color=f"C{chain}", lw=1.0)
            right.plot(values, color=f"C{chain}", lw=1.0, alpha=0.35)
        left.set_yticks([])
        right.set_xlim(0, draws.shape[1] - 1)
        for axis in (left, right):
            axis.set_title(labels.get(name, name), fontsize=9)
            axis.tick_params(labelsize=7)
    figure.suptitle("Trace in the sampler's coordinates (left: density per chain; right: draws)")
    return figure


def rank(idata: az.InferenceData) -> Figure:
    """Per sampled coordinate, each chain's histogram of its draws' ranks among all chains'
    (bins by Sturges' rule, doubled: ⌈2 log₂ draws⌉ + 1), stacked one chain a line, with the
    uniform level dashed."""
    names, labels = sampled_coordinates(idata), coordinate_labels(idata)
    columns = 4
    lines = int(np.ceil(len(names) / columns))
    margins = Margins(left=0.6, right=0.2, bottom=0.45, top=0.75, across=0.6, between=0.75)
    figure, axes = panels((12, 2.8 * lines), lines, columns, margins)
    for axis, name in zip(axes.ravel(), names, strict=False):
        draws = chain_draws(idata, name)
        ranks = rankdata(draws, method="average").reshape(draws.shape)
        bins = int(np.ceil(2 * np.log2(draws.shape[1])) + 1)
        edges = np.histogram_bin_edges(ranks, bins, range=(0, ranks.size))
        width = edges[1] - edges[0]
        gap = 2 / ranks.size  # one chain a line: a uniform histogram fills half of it
        for chain, chain_ranks in enumerate(ranks):
            level = np.histogram(chain_ranks, edges, density=True)[0]
            bottom = chain * gap
            bars = [
                [(x, bottom), (x, bottom + h), (x + width, bottom + h), (x + width, bottom)]
                for x, h in zip(edges[:-1], level, strict=True)
            ]
            axis.add_collection(
                PolyCollection(bars, facecolors=f"C{chain}", edgecolors="white", linewidths=1.0)
            )
            axis.axhline(bottom + level.mean(), color="k", ls="--", lw=1.5)
        axis.set_xlim(-0.05 * ranks.size, 1.05 * ranks.size)
        axis.set_ylim(0, (len(ranks) - 1) * gap + 1.5 / ranks.size)
        axis.set_yticks(np.arange(len(ranks)) * gap, labels=[str(c) for c in range(len(ranks))])
        axis.set_xlabel("Rank (all chains)", fontsize=8)
        axis.set_ylabel("Chain", fontsize=8)
        axis.set_title(labels.get(name, name), fontsize=9)
        axis.tick_params(labelsize=7)
    for axis in axes.ravel()[len(names) :]:
        axis.set_visible(False)
    figure.suptitle("Rank plots per chain (uniform when chains agree)")
    return figure


def pair(idata: az.InferenceData) -> Figure:
    """Every pair of sampled coordinates: the draws of all chains as points (the lower
    triangle; divergent transitions as red circles where the run records them), each
    coordinate's marginal density on the diagonal (no density scale); short axis labels, the
    title says what they are, with units."""
    names, labels = sampled_coordinates(idata), coordinate_labels(idata, short=True)
    count = len(names)
    figure = new_figure((12, 12))
    figure.subplots_adjust(top=0.93, left=0.07, bottom=0.06, right=0.98)
    grid = figure.add_gridspec(count, count)
    values = [chain_draws(idata, name).ravel() for name in names]
    diverging = (
        np.asarray(idata.sample_stats["diverging"]).ravel().astype(bool)
        if "diverging" in idata.sample_stats
        else None
    )
    rows: list = []  # each line's first panel: the line shares its y axis
    for column in range(count):
        diagonal = figure.add_subplot(grid[column, column])
        diagonal.plot(*density(values[column]), color="C0", lw=1.5)
        diagonal.set_yticks([])
        _outer_labels(diagonal, column, column, count, names, labels)
        for line in range(column + 1, count):
            axis = figure.add_subplot(
                grid[line, column], sharex=diagonal, sharey=rows[line - 1] if column else None
            )
            if not column:
                rows.append(axis)
            axis.plot(values[column], values[line], ".", ms=np.sqrt(2), mew=0, alpha=0.15)
            if diverging is not None and diverging.any():
                axis.plot(
                    values[column][diverging],
                    values[line][diverging],
                    "o",
                    color="red",
                    markeredgecolor="k",
                )
            _outer_labels(axis, line, column, count, names, labels)
    note = " (divergences in red)" if diverging is not None else ""
    figure.suptitle(
        f"Pairs in the sampler's coordinates{note}:\n{coordinate_note(idata)}", fontsize=10
    )
    return figure


def energy(idata: az.InferenceData) -> Figure:
    """ArviZ's NUTS energy plot: marginal energy against energy transitions, BFMI per chain."""
    figure, axes = panels((6, 4), margins=Margins(left=0.2, bottom=0.45, top=0.35))
    az.plot_energy(idata, ax=axes[0, 0])
    axes[0, 0].set_title("NUTS energy: marginal vs transition (BFMI in legend)")
    axes[0, 0].set_xlabel("energy − mean [-]")
    return figure


def _outer_labels(axis, line: int, column: int, count: int, names, labels) -> None:
    """Tick labels and axis labels on the pair plot's bottom line and first column only."""
    axis.tick_params(labelsize=7, labelbottom=line == count - 1, labelleft=column == 0)
    if line == count - 1:
        axis.set_xlabel(labels.get(names[column], names[column]), fontsize=9.5)
    if column == 0:
        axis.set_ylabel(labels.get(names[line], names[line]), fontsize=9.5)
