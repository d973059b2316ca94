"""The small committed example of a run (``--example``): its key figures and a README with the
verdict and the TIS table."""

from __future__ import annotations

from pathlib import Path

from brdf_infer._internal.atomic import atomic_write_bytes
from brdf_infer.model import fold_statement
from brdf_infer.report._results import indices_of, tis_fold
from brdf_infer.runs.folder import RunFolder
from brdf_infer.verdict import Verdict

EXAMPLE_FIGURES = ("brdf_bands", "tis_band", "hemisphere", "predictive", "raytrace", "instrument")


STUDY_FIGURES = (
    "compare",
    "sensitivity",
    "design",
)  # written by the studies into the run folder itself


def write_example(run: Path, example: Path) -> Path:
    """A small committed example: the key PNGs of ``run`` and a README with its verdict."""
    folder = RunFolder(run)
    summary = folder.summary()
    verdict = Verdict.from_json(summary["verdict"])
    bands = folder.bands()
    sources = [folder.figure_dir / f"{name}.png" for name in EXAMPLE_FIGURES]
    sources += [folder.file(f"{name}.png") for name in STUDY_FIGURES]
    names = [source.stem for source in sources if source.is_file()]
    for source in sources:
        if source.is_file():
            atomic_write_bytes(example / source.name, source.read_bytes())
    diagnostics = summary["diagnostics"]
    band = bands.get("tis")
    studies = (folder.studies() or {}).get("run", [])
    lines = [
        f"# Example report: scene `{summary['scene']}` ({summary['sampler']})",
        "",
        "Regenerate with `./dev run --full --example reports/example` (every study the scene can",
        "run; the full HTML report is written to `reports/lya/report.html`, which is not",
        "committed).",
        "",
        "**Studies run beside the posterior:** "
        + ("; ".join(studies) if studies else "none (the scene's one posterior)")
        + ".",
        "",
        f"**Verdict:** {verdict.text} (max R-hat {diagnostics['r_hat_max']:.3f}, min "
        f"bulk/tail ESS {diagnostics['ess_bulk_min']:.0f}/{diagnostics['ess_tail_min']:.0f}, "
        f"{diagnostics.get('divergences', 0)} divergences).",
        "",
        *(
            [
                "| θi [deg] | TIS median [%] | 68 % [%] | 95 % [%] |",
                "|---|---|---|---|",
                *(
                    f"| {band['theta_i_deg'][i]:g} | {100 * band['median'][i]:.2f} | "
                    f"{100 * band['lo68'][i]:.2f}–{100 * band['hi68'][i]:.2f} | "
                    f"{100 * band['lo95'][i]:.2f}–{100 * band['hi95'][i]:.2f} |"
                    for i in indices_of(band["theta_i_deg"], (0.0, 30.0, 50.0, 70.0, 80.0))
                ),
                "",
                f"TIS: {fold_statement(tis_fold(bands))}.",
            ]
            if band
            else []
        ),
        "",
        *(f"![{name}]({name}.png)" for name in names),
        "",
    ]
    return atomic_write_bytes(example / "README.md", "\n".join(lines).encode())
