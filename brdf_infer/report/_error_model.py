"""The report's Error model section: the run's noise sources with their sizes, the LOO-PIT of
this run and of its spread variant, PSIS-LOO and the comparison with the run's model variants."""

from __future__ import annotations

import numpy as np

from brdf_infer._internal import arviz as az
from brdf_infer.posterior import psis_loo, rank_models, relative_efficiency
from brdf_infer.report import _html
from brdf_infer.runs.folder import SUMMARY_FILE, VARIANTS_DIR, RunFolder
from brdf_infer.runs.records import PosteriorSummary
from brdf_infer.verdict import PARETO_K_LIMIT, limit_text

SPREAD_VARIANT = "spread"


def loo_pits(run: RunFolder, summary: PosteriorSummary) -> dict[str, tuple[list, float]]:
    """Error model name → (LOO-PIT values, KS p) of this run and of its spread variant."""
    pits = {}
    if "predictive" in summary:
        name = summary.get("error_model", {}).get("model", "this run")
        pits[f"{name} (this run)"] = (
            summary["predictive"]["loo_pit"],
            summary["predictive"]["loo_pit_ks_p"],
        )
    other = run.variant(SPREAD_VARIANT).read_json(SUMMARY_FILE, optional=True)
    if other is not None:
        pits["spread (earlier model)"] = (
            other["predictive"]["loo_pit"],
            other["predictive"]["loo_pit_ks_p"],
        )
    return pits


def error_model_table(summary: PosteriorSummary) -> str:
    """The noise sources of the run's error model with their sizes."""
    errors = summary.get("error_model")
    if not errors:
        return ""
    if errors["model"] == "spread":
        return (
            "<p>The earlier spread model: independent rows with σ² = "
            f"{errors['reflectance_rel']:g}² + s(θi)², s the inter-sample spread of ln R.</p>"
        )
    noise = summary.get("noise", {})

    judged = summary.get("learned", {})

    def learned(name: str) -> str:
        if name not in noise:
            return "off"
        value = noise[name]
        # a run written before the "learned" record: the data's say unknown, call it sampled
        words = judged[name]["words"] if name in judged else "sampled"
        return f"{value['median']:.3f} (95 %: {value['lo95']:.3f}–{value['hi95']:.3f}), {words}"

    repeatability = (
        learned("repeatability")
        if errors["repeatability"] == "learned"
        else f"{errors['repeatability']:g}, fixed"
    )
    calibration = errors.get("calibration", "none")
    calibration = (
        f"{errors['calibration_rel']:g} {calibration.replace('_', ' ')}, fixed"
        if calibration != "none"
        else "off"
    )
    angles = errors["propagate_angles"]
    images = errors["images_per_row"]
    if isinstance(images, dict):
        images = ", ".join(f"{n} ({name})" for name, n in images.items()) + ", else 1"
    coupling = {"camera_follows": "θs + ε", "camera_fixed": "θs − ε"}.get(
        errors.get("rotation_coupling", ""), ""
    )
    rows = [
        [
            "value noise e_i",
            f"σ of each row ÷ √n, n = {images} images (row's reflectance_err, else "
            f"reflectance_rel {errors['reflectance_rel']:g})",
        ],
        ["repeatability ν_i (per row)", repeatability],
        [
            "sample-to-sample u_j (per sample)",
            learned("sample_sd") if errors["hierarchical"] else "off",
        ],
        ["calibration κ (per reference measurement)", calibration],
        [
            "sample rotation ε (per series, sample, θi)",
            f"{errors['rotation_deg']:g}° through ln R ({errors['angle_method']}): θi + ε, "
            f"{coupling} ({errors.get('rotation_coupling', '')})"
            if angles
            else "off",
        ],
        [
            "camera position η (per row)",
            f"{errors['camera_deg']:g}° through ln R ({errors['angle_method']})"
            if angles
            else "off",
        ],
    ]
    return (
        "<p>Every noise source enters once (sizes in ln R). A sampled scale is called "
        "<em>learned</em> only where the data contract it (posterior variance at most half "
        "the prior's); otherwise it is <em>set by its prior</em>, whose scale is named.</p>"
        + _html.table(["source", "size"], rows)
    )


def variants_comparison(run: RunFolder, idata) -> str:
    """LOO comparison with model variants stored under ``run/variants/NAME``: the run's PSIS-LOO
    (:func:`~brdf_infer.posterior.psis_loo`) of each posterior.nc's pointwise terms, ranked
    with the differences' standard errors and stacking weights
    (:func:`~brdf_infer.posterior._loo.rank_models`, ArviZ's ``compare`` of the same terms)."""
    variants = {"this run": idata}
    stored = run.path / VARIANTS_DIR
    for name in sorted(p.name for p in stored.glob("*/")) if stored.is_dir() else []:
        if (posterior := run.variant(name).posterior_file).is_file():
            variants[name] = az.from_netcdf_groups(posterior, ("posterior", "log_likelihood"))
    if len(variants) < 2:
        return "<p>No model variants in this run to compare (variants/NAME/posterior.nc).</p>"
    loos = {
        name: psis_loo(
            np.asarray(idata.log_likelihood["obs"].values),
            None,
            relative_efficiency(idata.posterior),
        )
        for name, idata in variants.items()
    }
    return "<h3>Model variants (PSIS-LOO)</h3>" + _html.table(
        ["variant", "rank", "elpd_loo", "p_loo", "elpd_diff", "weight", "se", "dse"],
        [
            [
                r.name,
                rank,
                f"{r.loo.elpd_loo:.2f}",
                f"{r.loo.p_loo:.2f}",
                f"{r.d_elpd:.2f}",
                f"{r.weight:.2f}",
                f"{r.loo.se:.2f}",
                f"{r.dse:.2f}",
            ]
            for rank, r in enumerate(rank_models(loos))
        ],
    )


def loo_table(loo: dict) -> str:
    """PSIS-LOO of the run (``summary.json``'s ``predictive``): elpd_loo ± se, p_loo and the
    points with a high Pareto k."""
    return _html.table(
        ["PSIS-LOO", "value"],
        [
            ["elpd_loo", f"{loo['elpd_loo']:.2f} ± {loo['se']:.2f}"],
            ["p_loo", f"{loo['p_loo']:.2f}"],
            [
                f"points with k > {limit_text(loo.get('pareto_k_limit', PARETO_K_LIMIT))}, "
                "not refitted",
                int(loo["pareto_k_high"]),
            ],
            ["points refitted without them (exact LOO)", len(loo.get("loo_refit_rows", []))],
        ],
    )
