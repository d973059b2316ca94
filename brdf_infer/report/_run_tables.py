"""The report's section on the run itself: its settings, its priors (on the sampler's
coordinates), its data rows and the ArviZ summary of its parameters."""

from __future__ import annotations

import json

import numpy as np

from brdf_infer._internal import arviz as az
from brdf_infer.model import fold_statement
from brdf_infer.report import _html
from brdf_infer.report._instruments import MEANINGS
from brdf_infer.report._table_views import table_section
from brdf_infer.runs.records import PosteriorSummary

PRIOR_COORDINATES = {
    "brdf0": "ln BRDF0 [ln sr⁻¹]",
    "a1": "b1 = a1·90² [-]",
    "a2": "b2 = a2·90^(1+α) [-]",
    "a3": "b3 = a3·90^(2+α) [-]",
    "alpha": "α [-]",
    "theta_s0": "θs0 [deg]",
    "dphi_scale": "ln s, Δφ = s·(c1·θi + c2) of Eq. (8) [-]",
}


def priors_table(scene, summary: PosteriorSummary) -> str:
    """The scene's priors, and for each free parameter what the data did with it (the run's
    ``learned`` record: contraction 1 − var_post / var_prior, prior sensitivity, in words)."""
    judged = summary.get("learned", {})

    def data_words(name: str) -> list[str]:
        entry = judged.get(name)
        if entry is None:
            return ["-", "-"]
        return [f"{entry['contraction']:.2f}", entry["words"]]

    rows = [
        [name, PRIOR_COORDINATES[name], prior_text(prior), *data_words(name)]
        for name, prior in scene.priors.items()
    ]
    return _html.table(
        ["parameter", "prior on the coordinate", "prior", "contraction", "from the data"], rows
    )


def units(member) -> str:
    return ", ".join(f"{name} [{member.units[name]}]" for name in member.parameters)


def prior_text(prior) -> str:
    if prior.fixed:
        return f"fixed at {prior.value:g}"
    if prior.kind == "normal":
        return f"N({prior.loc:g}, {prior.scale:g})"
    if prior.kind == "uniform":
        return f"U[{prior.lower:g}, {prior.upper:g}]"
    bounds = (
        f"{'-inf' if prior.lower is None else f'{prior.lower:g}'}, "
        f"{'inf' if prior.upper is None else f'{prior.upper:g}'}"
    )
    return f"N({prior.loc:g}, {prior.scale:g}) on [{bounds}]"


def family_priors_table(member, summary: PosteriorSummary) -> str:
    """A family's default priors on its coordinates, with what the data did with each."""
    judged = summary.get("learned", {})
    rows = []
    for c in member.coordinates:
        entry = judged.get(c.site)
        learned = ["-", "-"] if entry is None else [f"{entry['contraction']:.2f}", entry["words"]]
        rows.append([c.site, c.description, prior_text(c.prior), *learned])
    return _html.table(["coordinate", "meaning", "prior", "contraction", "from the data"], rows)


def run_table(scene, rows, idata, summary: PosteriorSummary, member) -> str:
    """The run's settings: scene, model, instrument, measurements, sampler, seed, options, the
    Eq. (10) folding, versions and wall time [s]."""
    attrs = idata.posterior.attrs
    return _html.table(
        ["item", "value"],
        [
            ["scene", scene.name + (f": {scene.description}" if scene.description else "")],
            ["scene file", attrs["scene_file"]],
            # Eq. (7)'s units are in its priors table (the scene's [priors])
            ["model", member.name + ("" if member.paper_parameters else f" ({units(member)})")],
            [
                "instrument",
                f"{attrs.get('instrument', 'point')}: "
                + MEANINGS.get(attrs.get("instrument", "point"), ""),
            ],
            [
                "measurements",
                f"{', '.join(str(path) for _, path in scene.measurement_files)} ({len(rows)} rows)",
            ],
            ["sampler", f"{attrs['sampler']} {attrs['settings']}"],
            ["seed", attrs["seed"]],
            ["options", json.dumps(summary.get("options", {}))],
            [
                "Eq. (10) folding (the scene's [model] fold)",
                fold_statement(member.fold),
            ],
            ["versions", attrs["versions"]],
            [
                "wall time",
                f"{summary['seconds']['total']:.1f} s "
                f"(sampling {summary['seconds']['sampling']:.1f} s)",
            ],
            ["created", attrs.get("created", "")],
        ],
    )


DATA_TABLE_ROWS = 300  # more rows (a whole instrument table) are summarised per θi


def data_summary_table(rows) -> str:
    """A table too long to list (more than :data:`DATA_TABLE_ROWS` rows), one line per
    incidence angle: its rows, those in the plane of incidence, and the values' range."""
    name, unit = ("BRDF", "[sr⁻¹]") if rows.quantity == "brdf" else ("R", "[-]")
    phi = rows.phi_s_deg
    lines = []
    for angle in np.unique(rows.theta_i_deg):
        at = rows.theta_i_deg == angle
        in_plane = int(at.sum()) if phi is None else int(np.sum(at & np.isnan(phi)))
        values = rows.reflectance[at]
        lines.append(
            [
                f"{angle:g}",
                f"{int(at.sum())}",
                f"{in_plane}",
                f"{values.min():.3e} – {values.max():.3e}",
            ]
        )
    return (
        f"<p>{len(rows)} rows, too many to list here: one line per incidence angle (every row "
        "is in the measurement file the run names above).</p>"
        + _html.table(
            ["θi [deg]", "rows", "in the plane of incidence", f"{name} range {unit}"], lines
        )
    )


def data_table(rows) -> str:
    """The measured rows: series, sample, θi, θs and (with out-of-plane rows) φs [deg], the
    value (raw reflectance R [-] or BRDF [sr⁻¹]) and its σ; a longer table summarised
    (:func:`data_summary_table`)."""
    if len(rows) > DATA_TABLE_ROWS:
        return data_summary_table(rows)
    name, unit = ("BRDF", "[sr⁻¹]") if rows.quantity == "brdf" else ("R", "[-]")
    phi = rows.phi_s_deg
    errors = [None] * len(rows) if rows.reflectance_err is None else rows.reflectance_err
    return _html.table(
        [
            "series",
            "sample",
            "θi [deg]",
            "θs [deg]",
            *(["φs [deg]"] if phi is not None else []),
            f"{name} {unit}",
            f"σ_{name} {unit}",
        ],
        [
            [
                rows.series[i],
                rows.sample[i],
                f"{rows.theta_i_deg[i]:g}",
                f"{rows.theta_s_deg[i]:g}",
                *([] if phi is None else ["in plane" if np.isnan(phi[i]) else f"{phi[i]:.4g}"]),
                f"{rows.reflectance[i]:.3e}",
                "–" if errors[i] is None else f"{errors[i]:.2e}",
            ]
            for i in range(len(rows))
        ],
    )


def summary_table(idata, summary: PosteriorSummary, member) -> str:
    """ArviZ's summary of the family's free parameters in physical units."""
    table = az.summary(
        idata,
        var_names=[
            n for n in member.parameters if n not in summary["diagnostics"].get("fixed", [])
        ],
        round_to="none",
    )
    return _html.table(
        ["parameter", *table.columns],
        [[name, *(f"{v:.4g}" for v in table.loc[name])] for name in table.index],
    )


def run_section(scene, rows, idata, summary: PosteriorSummary, member) -> list[str]:
    """The run: its settings, its priors and its data."""
    return [
        "<h2>The run</h2>",
        run_table(scene, rows, idata, summary, member),
        "<h3>Priors</h3>",
        "<p>Each prior is on the coordinate named (the sampler's well-conditioned one). "
        + (
            "Together they are truncated to coatings that conserve energy (TIS below 0.95 at "
            "every θi in 0–85°). A parameter is <em>learned</em> when the data contract it "
            "(contraction 1 − var_post / var_prior ≥ 0.5), else <em>set by its prior</em>; "
            "<em>prior-sensitive</em>: power-scaling sensitivity to the prior ≥ 0.05.</p>"
            + priors_table(scene, summary)
            if member.paper_parameters
            else "</p>" + family_priors_table(member, summary)
        ),
        "<h3>Data</h3>",
        *table_section(summary),
        data_table(rows),
    ]
