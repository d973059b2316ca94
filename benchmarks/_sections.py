"""The sections of the benchmark report (``brdf-infer bench``), one function each: Markdown
lines from the rows the benchmarks measured, each section ending in a blank line."""

from __future__ import annotations

import time
from pathlib import Path

from benchmarks._batch import HEADERS as BATCH_HEADERS
from benchmarks._cache import HEADERS as CACHE_HEADERS
from benchmarks._export import ABG_HEADERS, GRID_HEADERS
from benchmarks._instrument import BIAS_HEADERS, ESS_HEADERS, NODE_HEADERS
from benchmarks._misspec import HEADERS as MISSPEC_HEADERS
from benchmarks._misspec import MisspecStudy
from benchmarks._misspec import section_text as misspec_text
from benchmarks._robustness import HEADERS as ROBUSTNESS_HEADERS
from benchmarks._robustness import LOADER_HEADERS
from benchmarks._sbc import HEADERS as SBC_HEADERS
from benchmarks._tables import markdown_table
from benchmarks._timing import machine_description
from brdf_infer.studies.raytrace import CHUNK_RAYS


def header_section(quick: bool, started: float) -> list[str]:
    """The title, the machine, the mode with the total wall time [s], and how to regenerate."""
    return [
        "# Benchmarks: error against run time",
        "",
        f"Machine: {machine_description()}.  ",
        f"Mode: {'quick' if quick else 'full'}; "
        f"total wall time {time.perf_counter() - started:.0f} s.  ",
        f"Regenerate: `brdf-infer bench{' --quick' if quick else ''}` (or `./dev run` then "
        "`.venv/bin/brdf-infer bench`). Every row was measured in this one run; run times exclude "
        "compilation, which is listed separately.",
        "",
    ]


def tis_section(
    tis_table: list, plot: Path, count: int, batch_seconds: float, batch_compile: float
) -> list[str]:
    """TIS of Eq. (9): each quadrature's error against its run time [µs], the plot, and the
    batched throughput."""
    return [
        "## TIS, Eq. (9)",
        "",
        "Relative error: the largest over θi = 5, 30, 50, 70° for `uv-paper`, against the exact "
        "1-D reduction at 256 nodes per panel (itself checked against 2-D adaptive quadrature of "
        "Eq. (9) to 1e-10 in `tests/test_tis.py`).",
        "",
        markdown_table(
            [
                "method",
                "grid",
                "BRDF evaluations",
                "max rel. error",
                "time per TIS [µs]",
                "compile [s]",
            ],
            [
                [
                    r.method,
                    r.resolution,
                    str(r.evaluations),
                    f"{r.max_rel_error:.1e}",
                    f"{1e6 * r.seconds_per_tis:.1f}",
                    f"{r.compile_seconds:.2f}",
                ]
                for r in tis_table
            ],
        ),
        "",
        f"![TIS error against time]({plot.name})",
        "",
        f"Batched: {count} TIS values (parameter draws × 90 incidence angles, exact 1-D, 64 nodes "
        f"per panel) in {batch_seconds:.3f} s = {count / batch_seconds:,.0f} TIS/s "
        f"(compile {batch_compile:.1f} s).",
        "",
    ]


def fit_section(fits: list) -> list[str]:
    """The fits' final χ² against run time."""
    return [
        "## Fits",
        "",
        "Final cost χ² = Σ((ln R_pred − ln R_obs)/σ)² over every measurement row, σ the row "
        "weights of least squares (the value's own noise, the angle errors through ln R and "
        "the Paule–Mandel repeatability at the Levenberg–Marquardt optimum; brdf_infer.fit.lsq), "
        "against run time. The optimistix rows reweight as they go and report their own final "
        "χ²; the paper's "
        "regression minimises a different objective (unweighted, fixed α and θs0, its own "
        "selection of rows), so its χ² is what its coefficients score here. Multi-start "
        "methods run the same starts; optimistix solves them in one vmapped call, SciPy one "
        "after another.",
        "",
        markdown_table(
            ["scene", "method", "final χ²", "starts at best", "time [s]", "compile [s]"],
            [
                [
                    r.scene,
                    r.method,
                    f"{r.cost:.6g}",
                    r.starts_at_best,
                    f"{r.seconds:.4f}",
                    f"{r.compile_seconds:.2f}",
                ]
                for r in fits
            ],
        ),
        "",
    ]


def sampler_section(samplers: list, reference: str) -> list[str]:
    """The samplers' errors in posterior sd against the reference, ESS per second."""
    return [
        "## Samplers",
        "",
        f"Default scene `lya`, all six parameters free. Error: the largest over the six "
        f"parameters of |estimate − reference| in units of the reference posterior sd, for the "
        f"mean and for the 2.5 %/97.5 % quantiles; reference: {reference}. ESS/s divides the "
        "smallest bulk ESS by the time of every iteration (NUTS warmup and draws, emcee "
        "burn-in and steps); setup is the emcee MAP search; JAX compile time (summed from "
        "JAX's compile events) is excluded from both and listed apart.",
        "",
        markdown_table(
            [
                "sampler",
                "run",
                "error of means [sd]",
                "error of 95 % quantiles [sd]",
                "min bulk ESS",
                "iterations [s]",
                "min ESS/s",
                "setup [s]",
                "compile [s]",
            ],
            [
                [
                    r.sampler,
                    r.settings,
                    f"{r.mean_error:.3f}",
                    f"{r.quantile_error:.3f}",
                    f"{r.min_ess_bulk:.0f}",
                    f"{r.sampling_seconds:.1f}",
                    f"{r.min_ess_bulk / r.sampling_seconds:.0f}",
                    f"{r.setup_seconds:.1f}",
                    f"{r.compile_seconds:.1f}",
                ]
                for r in samplers
            ],
        ),
        "",
    ]


def raytrace_section(traces: list, reference_rays: int, trace_plot: Path) -> list[str]:
    """The ray tracer's estimators (Sec. 6): MC error against run time, the plot."""
    return [
        "## Ray tracer (Sec. 6)",
        "",
        "Simulated dPs/Pi of one series II configuration with `uv-paper`: the estimator's own "
        "relative MC standard error, and the actual error against a next-event-estimation "
        f"run of {reference_rays:,} rays, against run time (rays in chunks of {CHUNK_RAYS:,}; "
        "the naive estimator is the forward ray trace of the paper, next-event estimation "
        "(nee) connects every sample hit to a point on AD). Efficiency = 1/(rel. error² × "
        "time): how much more accuracy a second buys.",
        "",
        markdown_table(
            [
                "configuration",
                "estimator",
                "rays",
                "rel. MC error",
                "actual rel. error",
                "time [s]",
                "rays/s",
                "efficiency [1/s]",
                "compile [s]",
            ],
            [
                [
                    r.configuration,
                    r.estimator,
                    f"{r.rays:,}",
                    f"{r.relative_se:.1e}",
                    f"{r.relative_error:.1e}",
                    f"{r.seconds:.3f}",
                    f"{r.rays_per_second:,.0f}",
                    f"{1 / (r.relative_se**2 * r.seconds):.2g}",
                    f"{r.compile_seconds:.2f}",
                ]
                for r in traces
            ],
        ),
        "",
        f"![ray tracer error against time]({trace_plot.name})",
        "",
    ]


def robustness_section(robustness: list) -> list[str]:
    """Default NUTS on the bundled scene and synthetic geometries."""
    return [
        "## Sampling robustness",
        "",
        "NUTS with default settings (4 chains × (1000 warmup + 1000 draws), target acceptance "
        "0.8) on the bundled scene for every seed, and on synthetic data (uv-paper, simulated "
        "through the generative error model) at geometries unlike the bundled one: a single "
        "series at θi = 10–70° with δ = −10…+15°, grazing incidence only (θi = 70–86°), and "
        "specular rows only (θs = θi, 4 samples). Every scene uses the default priors and "
        "error model of its file.",
        "",
        markdown_table(ROBUSTNESS_HEADERS, [row.cells for row in robustness]),
        "",
    ]


def loader_section(loaders: list) -> list[str]:
    """Every loader on generated bad inputs, and the first failures of each."""
    return [
        "## Bad input",
        "",
        "Every loader of user files on generated inputs (Hypothesis, the same inputs every run; "
        "`benchmarks/_loader_inputs.py`): measurement CSVs of both quantities with "
        "`phi_s_deg`, other delimiters, encodings and byte-order marks, line endings, quoting, "
        "huge, tiny and non-finite numbers, duplicated rows and columns; scene TOML with every "
        "table and key, wrong types, unknown keys, odd paths; Zemax .BSDF files with tabs, "
        "header lines out of order, counts that disagree with the data, Tristimulus, truncation; "
        "parameter JSON files and inline objects. Half the inputs are well-formed. Each must "
        "end in a result that holds what the loader promises or in one line naming the file "
        "or option (exit 2), with no file written; the last column counts every other outcome "
        "(`tests/test_loader_inputs.py` runs the same in its `slow` set).",
        "",
        markdown_table(LOADER_HEADERS, [row.cells for row in loaders]),
        *[f"- {row.loader}: {failure}" for row in loaders for failure in row.failures],
        "",
    ]


def sbc_section(calibrations: list, sbc_plots: list[Path]) -> list[str]:
    """Simulation-based calibration, with planted faults, and the ECDF plots."""
    return [
        "## Simulation-based calibration",
        "",
        "`brdf-infer sbc lya`: each replicate draws every parameter and latent from the "
        "physical prior (the scene's priors truncated to coatings that conserve energy, "
        "docs/posterior.md), simulates a data set at the bundled geometry through the scene's "
        "generative error model, samples it with NUTS (300 warmup, 200 draws thinned to 100) "
        "and ranks the "
        "truth. Quantities: the six parameters, TIS(70°) and the two learned noise scales. "
        "Verdict at a family-wise 1 % (Bonferroni over the three tests, χ², KS and 90 % "
        "coverage, of every quantity). The simulator is the likelihood itself (latent effects "
        "marginalised, angle slopes linearised at the truth), so SBC checks the inference given "
        "the model — sampler, reparametrisation, priors — and cannot see a wrong model. Faults "
        "planted in the inference only (`sbc --sigma-scale`, `--planted-fault`) must fail: the "
        "likelihood σ 35 % too wide (the learned repeatability and sample scales absorb most of "
        "it and the check flags it through those scales), the whitening's log-Jacobian dropped "
        "(`jacobian`), every free prior moved by one prior sd (`prior`). Wall time includes "
        "simulating and compiling; per replicate excludes compiling (replicates run one per "
        "core). The `abg` rows run the same check on the ABg family (`sbc --model abg`): its "
        "three parameters, TIS(70°) and the noise scales. The sampler maps ln BRDF0 below the "
        "energy boundary, so no NUTS trajectory ends on it (docs/posterior.md).",
        "",
        markdown_table(SBC_HEADERS, [row.cells for row in calibrations]),
        "",
        *(
            f"![SBC ECDF differences, {row.case}]({path.name})"
            for row, path in zip(calibrations[:2], sbc_plots, strict=True)
        ),
        "",
    ]


def misspec_section(study: MisspecStudy) -> list[str]:
    """Misspecified error models: what SBC cannot see, with truths from the prior and from the
    posterior."""
    before, prior_text, posterior_text, after = misspec_text(study)
    return [
        "## Misspecification: what SBC cannot see",
        "",
        before,
        "",
        prior_text,
        "",
        markdown_table(MISSPEC_HEADERS, [row.cells for row in study.prior]),
        "",
        posterior_text,
        "",
        markdown_table(MISSPEC_HEADERS, [row.cells for row in study.posterior]),
        "",
        after,
        "",
    ]


def export_section(grids: list, abgs: list) -> list[str]:
    """Exported .BSDF tables' hemisphere integrals and the ABg fits."""
    return [
        "## Exports",
        "",
        "Zemax .BSDF tables (`brdf-infer export`): each table's own hemisphere integral "
        "(trapezoid in the specular frame, dΩ = sin r dr dψ) against the exact Eq. (9) TIS "
        "that its TIS line carries, the worst over θi = 0, 5, …, 85°, per grid step; time to "
        "evaluate the tables (after compiling). Default: 5° / 1°.",
        "",
        markdown_table(GRID_HEADERS, [row.cells for row in grids]),
        "",
        "ABg fits (`export --format abg`): A·I(B, g) recomputed with a finer quadrature than "
        "the one that set A, against the model's TIS; the range over θi of the cos θ sin θ-"
        "weighted rms ln-BSDF error; time for all angles of incidence.",
        "",
        markdown_table(ABG_HEADERS, [row.cells for row in abgs]),
        "",
    ]


def family_section(quadratures: list, comparison: dict, quick: bool) -> list[str]:
    """The lobe families' TIS quadratures and ``brdf-infer compare lya``."""
    return [
        "## Model families",
        "",
        "TIS of the lobe families (`abg`: A = 2e-3 sr⁻¹, B = 5e-3, g = 1.8; `harvey-shack`: "
        "b0 = 0.4 sr⁻¹, L = 0.05, S = −2.2) by the unit-disk quadrature against SciPy's "
        "adaptive `dblquad` of the BRDF over the hemisphere (rtol 1e-11), the worst over "
        "θi = 0, 40, 80°; time per integral after compiling. `fit` is used inside the ABg "
        "export fit and for every TIS the families report, `precise` to set the ABg export's "
        "A, `check` to verify. "
        "`lambertian`'s TIS is exact.",
        "",
        markdown_table(
            ["family", "quadrature", "max abs(rel. error)", "time [µs]"],
            [row.cells for row in quadratures],
        ),
        "",
        "`brdf-infer compare lya` (every family by NUTS, "
        f"{'300' if quick else '4 × 1000'} draws; PSIS-LOO on the leave-one-out conditionals):"
        f" {comparison['seconds']:.0f} s.",
        "",
        markdown_table(
            ["family", "elpd_loo ± se", "Δelpd ± dse", "weight", "max Pareto k", "TIS(70°) [%]"],
            [
                [
                    m["name"],
                    f"{m['elpd_loo']:.1f} ± {m['se']:.1f}",
                    f"{m['d_elpd']:.1f} ± {m['dse']:.1f}",
                    f"{m['weight']:.2f}",
                    f"{m['pareto_k_max']:.2f}",
                    "{:.2f} ({:.2f}–{:.2f})".format(
                        *(100 * m["tis70"][k] for k in ("median", "lo95", "hi95"))
                    ),
                ]
                for m in comparison["models"]
            ],
        ),
        "",
    ]


def batch_section(batches: list) -> list[str]:
    """``brdf-infer batch`` against separate processes."""
    return [
        "## Batch inference",
        "",
        "`brdf-infer batch` over N synthetic scenes (the bundled rows, each scene's reflectances "
        "scaled by its own factor; NUTS 4 × (1000 + 1000) per scene, one CPU thread per scene) "
        "against separate `brdf-infer posterior` processes of the same scenes (persistent "
        "compilation cache warm; the best of two after one that warms it). Wall time per scene "
        "includes compiling once per batch, sampling, and writing each run folder. On this "
        "2-core CPU the batch is bounded by the NUTS work itself (≈ 10 s of sampling per "
        "scene at two threads); the 64-scene row and device-count scaling are not run here "
        "(no accelerator; see the README).",
        "",
        markdown_table(BATCH_HEADERS, [row.cells for row in batches]),
        "",
    ]


def cache_section(caches: list) -> list[str]:
    """Fresh processes with an empty and a warm compilation cache."""
    return [
        "## Compilation cache",
        "",
        "Fresh processes with an empty persistent cache folder (`BRDF_INFER_CACHE`), then "
        "the same command again: wall time end to end (process start, imports, compiling or "
        "loading the programs, sampling, files; `run` also the paper fit, least squares, the "
        "spread variant, the two other instrument models' posteriors, ray traces and the "
        "report), the NUTS compile time of the posterior (`summary.json` seconds.compile) "
        "and the number of XLA programs compiled and loaded from the cache (from "
        "`JAX_LOG_COMPILES`).",
        "",
        markdown_table(CACHE_HEADERS, [row.cells for row in caches]),
        "",
    ]


def instrument_section(kernel_nodes: list, kernel_ess: list, biases: list) -> list[str]:
    """The instrument kernels: error and cost, NUTS under each, the synthetic bias experiment."""
    return [
        "## Instrument kernels",
        "",
        'What a raw reflectance is (README, "Instrument models"): `point` is Eq. (6); '
        "`aperture` and `image` are Σ w_k BRDF_k over nodes compressed from 2^16 (`image`: "
        "2^18) Sobol points of the beam footprint and the detector aperture. Error of the "
        "compressed kernel against its full cubature (worst row of the 42, worst of two "
        "parameter sets unlike each other) and against the ray tracer (NEE, series II at "
        "`uv-paper`; its own MC σ beside it); cost of ln R and its gradient for all rows "
        "(jitted, one call).",
        "",
        markdown_table(NODE_HEADERS, [row.cells for row in kernel_nodes]),
        "",
        "NUTS on the bundled data under each instrument model (same settings and seed; min "
        "bulk ESS over the six parameters per second of sampling; the issue asks for at least "
        "0.25 of `point`):",
        "",
        markdown_table(ESS_HEADERS, [row.cells for row in kernel_ess]),
        "",
        "Synthetic experiment (`brdf_infer.studies.instrument_bias`): the ray tracer's dPs/Pi "
        "(`aperture`) or Eq. (2) image ratio (`image`) at `uv-paper` for all 42 rows, times "
        "the noise of the scene's generative error model, analysed by Eq. (6) and by the "
        "generating kernel (NUTS 2 × (500 + 500) per data set); fraction of seeds whose 95 % "
        "interval covers the truth, and the mean posterior median over the truth.",
        "",
        markdown_table(BIAS_HEADERS, biases),
        "",
    ]
