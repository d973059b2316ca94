"""Figures and HTML page of simulation-based calibration (``brdf-infer sbc``), and the folder
they are written to with the result."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from brdf_infer.model import FAMILIES
from brdf_infer.report import _html
from brdf_infer.runs.folder import SBC_FILE, RunFolder
from brdf_infer.scene.settings import PLANTED_FAULTS
from brdf_infer.studies.sbc import COVERAGE_LEVELS, HISTOGRAM_BINS, SbcResult
from brdf_infer.studies.uniformity import ecdf_band, uniform_rank_band
from brdf_infer.verdict import ALL_PASS, Verdict

LABELS = {
    "brdf0": "brdf0 [sr⁻¹]",
    "a1": "a1 [deg⁻²]",
    "a2": "a2 [deg^(−1−α)]",
    "a3": "a3 [deg^(−2−α)]",
    "alpha": "α [-]",
    "theta_s0": "θs0 [deg]",
    "dphi_scale": "Δφ factor (Eq. 8) [-]",
    "tis70": "TIS(70°) [-]",
    "tis70_measured": "TIS(70°), sample(s) measured [-]",
    "tis70_new_part": "TIS(70°), a new part [-]",
    "sample_sd": "sample sd τ [ln R]",
    "repeatability": "repeatability σ_rep [ln R]",
}
for _member in FAMILIES.values():  # the other families' physical parameters
    LABELS.update({n: f"{n} [{_member.units[n]}]" for n in _member.parameters if n not in LABELS})


def label(name: str) -> str:
    """A ranked quantity's label with its unit; ``calibration_G``: the G-th calibration
    factor κ (brdf_infer.studies.sbc.target_quantities)."""
    if name.startswith("calibration_"):
        return f"calibration factor κ{name.removeprefix('calibration_')} [ln R]"
    return LABELS[name]


def png(figure: Figure, dpi: int = 90) -> bytes:
    """The figure as PNG bytes (no pyplot, no backend switching)."""
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=dpi)
    return buffer.getvalue()


def _grid(count: int) -> tuple[Figure, np.ndarray]:
    columns = 4
    lines = int(np.ceil(count / columns))
    figure = Figure(figsize=(12, 2.8 * lines), layout="constrained")
    axes = figure.subplots(lines, columns, squeeze=False).ravel()
    for axis in axes[count:]:
        axis.set_visible(False)
    return figure, axes


def rank_histograms(result: SbcResult) -> Figure:
    """Rank histograms with the 99 % range of a bin's count under uniform ranks."""
    settings = result.settings
    figure, axes = _grid(len(result.quantities))
    edges = np.linspace(0, settings.draws + 1, HISTOGRAM_BINS + 1)
    low, high = uniform_rank_band(settings.replicates, HISTOGRAM_BINS)
    for axis, name in zip(axes, result.quantities, strict=False):
        axis.axhspan(low, high, color="0.85", label="99 % range, uniform")
        axis.axhline(settings.replicates / HISTOGRAM_BINS, color="0.5", lw=0.8)
        axis.hist(result.ranks[name], bins=edges, color="C0", alpha=0.85)
        axis.set_title(f"{label(name)}\nχ² p = {result.chi2_p[name]:.2g}", fontsize=9)
        axis.set_xlabel(f"rank of the truth among {settings.draws} draws")
        axis.set_ylabel("replicates")
    axes[0].legend(fontsize=7, loc="lower left")
    figure.suptitle(
        f"SBC rank histograms, {settings.replicates} replicates (flat within the grey band "
        "when the posterior is calibrated)"
    )
    return figure


def ecdf_differences(result: SbcResult) -> Figure:
    """ECDF of the normalised ranks minus the uniform CDF, with simultaneous 95 % bands."""
    settings = result.settings
    points = np.linspace(0.0, 1.0, 101)[1:-1]
    low, high = ecdf_band(settings.replicates, points)
    figure, axes = _grid(len(result.quantities))
    for axis, name in zip(axes, result.quantities, strict=False):
        fractions = (np.asarray(result.ranks[name]) + 0.5) / (settings.draws + 1)
        ecdf = np.mean(fractions[:, None] <= points[None, :], axis=0)
        axis.fill_between(points, low - points, high - points, color="0.85", label="95 % band")
        axis.axhline(0.0, color="0.5", lw=0.8)
        axis.plot(points, ecdf - points, color="C3")
        axis.set_title(f"{label(name)}\nKS p = {result.ks_p[name]:.2g}", fontsize=9)
        axis.set_xlabel("normalised rank [-]")
        axis.set_ylabel("ECDF − uniform [-]")
    axes[0].legend(fontsize=7, loc="lower left")
    figure.suptitle(
        "SBC ECDF differences with simultaneous 95 % bands (Säilynoja et al. 2022): "
        "∩-shaped = posterior too wide, ∪-shaped = too narrow, tilted = biased"
    )
    return figure


def sbc_figures(result: SbcResult) -> dict[str, bytes]:
    """PNG bytes of the SBC figures, by file stem."""
    return {
        "sbc_ranks": png(rank_histograms(result)),
        "sbc_ecdf": png(ecdf_differences(result)),
    }


SCOPE = (
    "<p><strong>What this checks, and what it cannot.</strong> The data sets are simulated by "
    "the scene's own model, the same one the likelihood is (the latent sample, calibration and "
    "angle effects marginalised, the angle slopes linearised at the truth). SBC therefore checks "
    "the inference <em>given that model</em>: the NUTS sampler and its adaptation, the whitened "
    "reparametrisation and its Jacobian, and that the inference's priors are the simulator's. "
    "It cannot see a wrong model: a wrong calibration size, a wrong rotation coupling, a wrong "
    "number of images per row or the linearisation of the angle slopes would be in the "
    "simulated data and in the inference alike, and the check passes. A calibrated verdict is "
    "no evidence that the error model is right.</p>"
)


def _planted(settings) -> list[str]:
    """A paragraph per fault planted in the inference (none as built)."""
    lines = []
    if settings.sigma_scale != 1:
        lines.append(
            f"<p><strong>Planted fault:</strong> the inference used a likelihood σ scaled by "
            f"{settings.sigma_scale:g}; a working check must fail. The learned noise scales "
            "(sample sd, repeatability) absorb most of it, so the check fails through those "
            "scales rather than the BRDF parameters.</p>"
        )
    if settings.planted_fault is not None:
        lines.append(
            f"<p><strong>Planted fault ({settings.planted_fault}):</strong> "
            f"{PLANTED_FAULTS[settings.planted_fault]}; a working check must fail.</p>"
        )
    return lines


def sbc_page(result: SbcResult, figures: dict[str, bytes]) -> str:
    """A self-contained HTML page: verdict, tests and coverage table, figures."""
    settings = result.settings
    lines = () if result.passed else tuple(result.failures)
    verdict = _html.verdict_box(Verdict(lines)).replace(ALL_PASS, "the posterior is calibrated")
    rows = []
    for name in result.quantities:
        rows.append(
            [
                label(name),
                f"{result.chi2_p[name]:.3f}",
                f"{result.ks_p[name]:.3f}",
                *(f"{result.coverage[level][name]:.1%}" for level in COVERAGE_LEVELS),
            ]
        )
    low, high = result.coverage_range[0.9]
    sections = [
        verdict,
        *_planted(settings),
        "<p>Each replicate draws the parameters and every latent from the scene's prior, "
        "simulates a data set at the scene's geometry through the scene's generative model, "
        f"samples its posterior with NUTS ({settings.warmup} warmup, "
        f"{settings.draws} × {settings.thin} draws, thinned by {settings.thin}) and ranks the "
        f"truth among the draws. Each of the m = {len(result.quantities)} quantities has three "
        "tests (χ², KS, 90 % coverage), and each fails below 0.01/(3m): the family-wise level "
        f"is 1 %. The 90 % coverage must lie in [{low:.1%}, {high:.1%}]. Quantities the scene "
        "fixes are not ranked.</p>",
        SCOPE,
        _html.table(
            ["quantity", "χ² p", "KS p", "50 % coverage", "90 % coverage", "95 % coverage"], rows
        ),
        f"<p>{settings.replicates} replicates in {result.seconds:.0f} s "
        f"({result.compile_seconds:.0f} s compiling); "
        f"{int(np.sum(result.divergences > 0))} replicate(s) with divergent transitions.</p>",
        _html.figure(figures["sbc_ranks"], "Rank histograms."),
        _html.figure(figures["sbc_ecdf"], "ECDF differences."),
    ]
    return _html.page("Simulation-based calibration", sections)


def write_sbc(out: Path, result: SbcResult) -> list[Path]:
    """sbc.json, the figures (PNG) and sbc.html into ``out``, atomically."""
    folder = RunFolder(out)
    folder.path.mkdir(parents=True, exist_ok=True)
    paths = [folder.write_json(SBC_FILE, result.as_json())]
    figures = sbc_figures(result)
    for name, png in figures.items():
        paths.append(folder.write_bytes(f"{name}.png", png))
    paths.append(folder.write_bytes("sbc.html", sbc_page(result, figures).encode()))
    return paths
