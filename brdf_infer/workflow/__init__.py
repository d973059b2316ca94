"""The main job as one library call: paper fit, least squares, the scene's NUTS posterior,
its products and the report, into one run folder. The studies a scene asks for in
``[studies]`` (other error models, other instrument models, ray traces of the posterior, a
model comparison, the sensitivity to the error-model assumptions) run after it; none runs
unless asked (``RunSettings.studies`` overrides the scene's table, :func:`full_studies` is
everything the scene can do). For a model family other
than ``strumik2024`` the paper fit (Eq. 7's regression), the instrument study, the ray
traces (whose surface scatters by Eq. 7) and the sensitivity study (π·BRDF0 is Eq. 7's) are
left out.

``brdf-infer run`` parses its options and calls :func:`run`; a notebook calls it the same way:

    from brdf_infer.scene import load_scene
    from brdf_infer.workflow import run
    scene = load_scene("lya")
    result = run(scene, scene.load_measurements(), Path("reports/lya"))
    result.verdict.text, result.posterior["tis_70deg"]

Before anything is written or sampled, :func:`run` checks the rows and then the fits for
plausibility (:mod:`brdf_infer.verdict.plausibility`: angles in radians, values in percent, a fit
whose π·BRDF0 or TIS exceeds 1) and stops on the first that fails, unless
``RunSettings(force=True)``; then the run goes on and its verdict names every failed check.

The fit summaries (:func:`paper_fit_summary`, :func:`lsq_summary`) are the JSON objects of
``brdf-infer fit --json``. The job's numbered steps and the studies, one function each, are in
``_studies`` (private to this package). Posteriors of many scenes in one compiled program, over
one or several processes, are :mod:`brdf_infer.workflow.batch`.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from brdf_infer._internal.precision import ensure_float64
from brdf_infer._internal.step_clock import StepClock
from brdf_infer.runs.folder import FIT_LSQ_FILE, FIT_PAPER_FILE, RunFolder
from brdf_infer.runs.folder import STUDIES_FILE as STUDIES_FILE  # the old name, kept
from brdf_infer.runs.records import PosteriorSummary
from brdf_infer.scene import Scene, Studies
from brdf_infer.scene.settings import AUTO_FAMILIES, AUTO_MODEL, LSQ_STARTS, RunSettings
from brdf_infer.tables.measurements import Measurements
from brdf_infer.verdict import Verdict
from brdf_infer.verdict.plausibility import Implausible
from brdf_infer.workflow._studies import (
    Job,
    compare_study,
    design_study,
    error_model_posterior,
    instrument_study,
    sensitivity_study,
)

RUN_TRACE_RAYS = 2**18  # ~0.05 % MC error per configuration (NEE)
RUN_TRACE_DRAWS = 64
RUN_TRACE_BAND_RAYS = 16_384  # per draw and configuration


def _silent(message: str) -> None:
    del message


def full_studies(scene: Scene) -> Studies:
    """Every study the scene can run: the other error model, every instrument model its
    geometry supports, ray traces where it has a ``[raytrace]`` setup, the comparison of
    the reference model with ABg and Lambertian (or the scene's own list), the sensitivity
    to the error-model assumptions where the scene has a TIS, and where to measure next (the
    scene's ``[studies] design`` target, else TIS(70°) where the scene has a TIS, else
    π·BRDF0)."""
    from brdf_infer.model.error_model import ERROR_MODELS
    from brdf_infer.studies.instrument_comparison import supported_instruments

    return Studies(
        error_models=tuple(m for m in ERROR_MODELS if m != scene.errors.model),
        instruments=tuple(m for m in supported_instruments(scene) if m != scene.instrument.model),
        raytrace=scene.raytrace is not None,
        compare=scene.studies.compare or ("strumik2024", "abg", "lambertian", "lambertian+abg"),
        sensitivity=scene.model.out_of_plane,
        design=scene.studies.design or ("tis:70" if scene.model.out_of_plane else "pi_brdf0"),
    )


def not_run(scene: Scene, studies: Studies) -> list[str]:
    """The studies of :func:`full_studies` that ``studies`` leaves out, one phrase each."""
    done = set(studies.requested())
    return [study for study in full_studies(scene).requested() if study not in done]


@dataclass
class RunResult:
    """What :func:`run` made (``as_json`` is the JSON of ``brdf-infer run --json``).

    Attributes:
        out: the run folder.
        report: the HTML report.
        model: the model family sampled.
        verdict: the run's one verdict (:mod:`brdf_infer.verdict`), as the report shows it.
        paper_fit, lsq: the fit summaries (``paper_fit``: the article's regression of Eq. 7,
            None when another family is run).
        posterior: the posterior summary (``summary.json``).
        comparison: the PSIS-LOO comparison (``compare.json``), where the scene asks for one.
        seconds: wall time.
        steps: wall time of each step [s] (``step_seconds`` in the JSON): ``fits`` (the
            checks of the rows and the settings, the paper fit and least squares),
            ``posterior``, ``studies`` (none: 0) and ``report``.
    """

    out: Path
    report: Path
    model: str
    verdict: Verdict
    paper_fit: dict[str, Any] | None
    lsq: dict[str, Any]
    posterior: PosteriorSummary
    comparison: dict[str, Any] | None
    seconds: float
    steps: dict[str, float] = dataclasses.field(default_factory=dict)

    def as_json(self) -> dict[str, Any]:
        payload = {
            "out": str(self.out),
            "report": str(self.report),
            "model": self.model,
            "verdict": self.verdict.as_json(),
            "paper_fit": self.paper_fit,
            "lsq": self.lsq,
            "posterior": self.posterior,
            "seconds": self.seconds,
            "step_seconds": self.steps,
        }
        if self.comparison is not None:
            payload["comparison"] = self.comparison
        return payload


def fit_checks(scene: Scene, measurements: Measurements, fit: dict[str, Any]) -> list[Implausible]:
    """The plausibility checks (:mod:`brdf_infer.verdict.plausibility`) of a fit summary
    (:func:`paper_fit_summary` or :func:`lsq_summary`): π·BRDF0 and
    the TIS at the scene's incidence angles."""
    from brdf_infer.model import family, run_family_name
    from brdf_infer.model.params import Params
    from brdf_infer.verdict import plausibility

    member = family(run_family_name(fit), scene.model.fold, scene.model.constants)
    what = "the paper fit" if fit["method"] == "paper" else "the least-squares fit"
    if member.paper_parameters:
        return plausibility.fit_checks(scene, measurements, Params(**fit["params"]), what)
    return plausibility.family_fit_checks(
        scene, measurements, member, fit["params"], f"{what} of {member.name}"
    )


def paper_fit_summary(
    scene: Scene, measurements: Measurements, selection: str | None = None
) -> dict[str, Any]:
    """The paper's regression (Sec. 4.2) as the JSON of ``fit --method paper``."""
    from brdf_infer.fit.paper import paper_fit
    from brdf_infer.model.params import params_to_dict

    start = time.perf_counter()
    result = paper_fit(scene, measurements, selection=selection)
    seconds = time.perf_counter() - start
    return {
        "method": "paper",
        "scene": scene.name,
        "selection": selection or scene.paper_fit.selection,
        "params": params_to_dict(result.params),
        "sigma_e": result.sigma_e,
        "sigma_re": result.sigma_re,
        "n_points": result.n_points,
        "seconds": seconds,
    }


def lsq_summary(
    scene: Scene,
    measurements: Measurements,
    member=None,
    *,
    starts: int = LSQ_STARTS,
    solver: str = "lm",
    seed: int = 0,
    scale_covariance: bool = False,
    progress: Callable[[str], None] = _silent,
    paper: dict[str, float] | None = None,
) -> dict[str, Any]:
    """The least-squares fit of ``member`` (default: the scene's family) as the JSON of
    ``fit --method lsq`` (warnings also to ``progress``): ``sigma`` is the 1σ as asked (scaled
    by √(χ²/dof) with ``scale_covariance``), ``sigma_scaled`` always the scaled one, next to
    ``chi2_dof`` and the ``fit_quality`` statement (:mod:`brdf_infer.fit.quality`); for Eq. (7)'s
    family ``paper_fit_cost``: the χ² of the paper fit's parameters ``paper`` under the same
    weights (None: fitted here)."""
    from brdf_infer.fit.lsq import fit_lsq
    from brdf_infer.fit.quality import FitQuality
    from brdf_infer.model import family

    if member is None:
        member = family(scene.model.family, scene.model.fold, scene.model.constants)
    progress(f"least squares of {member.name}: {starts} starts, solver {solver} ...")
    result = fit_lsq(
        scene,
        measurements,
        member,
        starts=starts,
        solver=solver,
        seed=seed,
        scale_covariance=scale_covariance,
    )
    for warning in result.warnings:
        progress(f"warning: {warning}")
    dof = result.n_points - len(result.free)
    learned = scene.errors.model == "generative" and scene.errors.learns_repeatability
    learned = learned and dof > 0
    quality = FitQuality(
        result.cost,
        dof - learned,  # σ_rep is one more parameter fitted to the rows
        result.repeatability if learned else None,
        result.repeatability_check,
        scene.errors.expected_repeatability,
        result.residual_trend_p_values,
        result.residual_trend_statistic,
        result.residual_trend_detectable,
        _row_variance(result) if learned else None,
    )
    summary = {
        "method": "lsq",
        "model": member.name,
        "scene": scene.name,
        "params": result.physical,
        "cost": result.cost,
        "reduced_chi2": result.reduced_chi2,
        **quality.as_json(),
    }
    if member.paper_parameters:
        summary["paper_fit_cost"] = _paper_fit_cost(scene, measurements, result, paper)
    return summary | _lsq_details(result, quality, member.parameters)


def _row_variance(result) -> float:
    """The rows' typical variance besides the learned repeatability [ln R²]: the median of
    each row's σ² less σ_rep²."""
    return float(np.median(np.asarray(result.row_sigma) ** 2 - result.repeatability**2))


def _lsq_details(result, quality, names) -> dict[str, Any]:
    """The keys of the least-squares JSON after its parameters and quality (1σ, correlations,
    starts, row weights, warnings)."""
    from brdf_infer.fit.quality import scaled_sigma

    return {
        "sigma": result.sigma,
        "sigma_scaled": result.sigma
        if result.covariance_scaled
        else scaled_sigma(result.sigma, quality.sigma_factor),
        "correlation": result.correlation.tolist(),
        "correlation_names": list(names),
        "internal": result.internal,
        "sigma_internal": result.sigma_internal,
        "condition_number": result.condition_number,
        "covariance_scaled": result.covariance_scaled,
        "n_points": result.n_points,
        "free": list(result.free),
        "starts": result.starts,
        "starts_converged": result.starts_converged,
        "start_costs": result.start_costs.tolist(),
        "start_status": result.start_status,
        "solver": result.solver,
        "seconds": result.seconds,
        "compile_seconds": result.compile_seconds,
        "row_sigma": result.row_sigma.tolist(),
        "repeatability": result.repeatability,
        "repeatability_p_value": None
        if result.repeatability_check is None
        else result.repeatability_check.p_value,
        "reweightings": result.reweightings,
        "warnings": result.warnings,
    }


def _paper_fit_cost(scene: Scene, measurements: Measurements, result, paper) -> float:
    """χ² of the paper fit's parameters (``paper``; None: fitted here) under the row weights
    least squares settled on."""
    from brdf_infer.fit.paper import paper_fit
    from brdf_infer.model.params import Params
    from brdf_infer.predict.observations import build_observation_model

    model = build_observation_model(scene, measurements).with_sigma(result.row_sigma)
    paper_params = paper_fit(scene, measurements).params if paper is None else Params(**paper)
    return float(model.chi2(paper_params))


def run_traces(scene: Scene, measurements: Measurements, posterior_run) -> list[dict]:
    """The main job's ray traces: the posterior (band over draws), and the scene's reference
    parameter set (e.g. ``uv-paper``) where it names one."""
    from brdf_infer.model.params import PARAMETER_SETS
    from brdf_infer.posterior import draws_params
    from brdf_infer.studies.raytrace import raytrace_payload, raytrace_posterior_payload, thin_draws

    draws = thin_draws(draws_params(posterior_run.idata.posterior), RUN_TRACE_DRAWS)
    traces = [
        raytrace_posterior_payload(
            scene, measurements, draws, "posterior", rays=RUN_TRACE_BAND_RAYS
        )
    ]
    name = scene.outputs.reference_params
    if name is not None:
        traces.append(
            raytrace_payload(scene, measurements, PARAMETER_SETS[name], name, rays=RUN_TRACE_RAYS)
        )
    return traces


def run(
    scene: Scene,
    measurements: Measurements,
    out: Path,
    settings: RunSettings = RunSettings(),
    *,
    example: Path | None = None,
    progress: Callable[[str], None] = _silent,
) -> RunResult:
    """The main job on ``scene`` into the folder ``out`` (module docstring).

    Args:
        scene: the scene.
        measurements: its rows.
        out: the run folder (created; result files are written atomically).
        settings: NUTS and least-squares settings, the studies, and ``force``.
        example: also write the small committed example report here.
        progress: called with one line per step.

    Raises:
        BadInputError: a setting out of range, an unknown family or study, (without
            ``settings.force``) a failed plausibility check, or another process writing
            ``out``; nothing is written then.
    """
    ensure_float64()
    from brdf_infer._internal.outlock import writing

    with writing(out, "run"):  # one writer; an interrupted run leaves ``out`` incomplete
        return _run(scene, measurements, out, settings, example=example, progress=progress)


def _run(
    scene: Scene,
    measurements: Measurements,
    out: Path,
    settings: RunSettings,
    *,
    example: Path | None,
    progress: Callable[[str], None],
) -> RunResult:
    """:func:`run` with ``out`` held."""
    from brdf_infer.posterior import build_model
    from brdf_infer.verdict.plausibility import measurement_checks, require_plausible

    clock = StepClock()
    name = settings.model or scene.model.family
    studies = settings.studies if settings.studies is not None else scene.studies
    chosen = None
    if name == AUTO_MODEL:  # the rows and studies checked first: the family decides the rest
        _check_studies(scene, list(studies.instruments), studies.sensitivity)
        require_plausible(measurement_checks(scene, measurements), settings.force)
        chosen = _auto_family(scene, measurements, progress)
        name = chosen.table[0]["name"] if chosen.table else scene.model.family
        studies = dataclasses.replace(studies, compare=())  # the comparison is made
    # an unknown family fails before any work; the studies written for Eq. (7) need its family
    eq7 = build_model(scene, measurements, name).family.paper_parameters
    error_models = [m for m in studies.error_models if m != scene.errors.model]
    instruments = [m for m in studies.instruments if m != scene.instrument.model] if eq7 else []
    traces = studies.raytrace and scene.raytrace is not None and eq7
    sensitive = studies.sensitivity and eq7
    designed = bool(studies.design) and eq7
    _check_studies(scene, instruments, sensitive)
    implausible = measurement_checks(scene, measurements)
    require_plausible(implausible, settings.force)
    steps = 4 + len(error_models) + bool(instruments) + traces + bool(studies.compare)
    job = Job(
        scene,
        measurements,
        out,
        settings,
        progress,
        name,
        studies,
        eq7,
        steps + sensitive + designed,
    )
    paper = _paper_fit(job, implausible)
    lsq = _least_squares(job, implausible, paper)
    forced = _write_fits(job, implausible, paper, lsq)
    comparison = None
    if chosen is not None:
        from brdf_infer.report import write_comparison

        write_comparison(out, chosen)
        comparison = chosen.as_json()
    options = {
        "chains": settings.chains,
        "draws": settings.draws,
        "warmup": settings.warmup,
        "seed": settings.seed,
        "model": name,
    }
    clock.lap("fits")
    posterior = _posterior(job, options, forced, lsq)
    clock.lap("posterior")
    for error_model in error_models:
        error_model_posterior(job, error_model, options, forced)
    if instruments:
        instrument_study(job, instruments, options, posterior)
    if traces:
        _raytrace_study(job, posterior)
    if studies.compare:
        comparison = compare_study(job)
    if sensitive:
        sensitivity_study(job)
    if designed:
        design_study(job)
    clock.lap("studies")
    report, verdict = _report(job, example)
    clock.lap("report")
    return RunResult(
        out=out,
        report=report,
        model=name,
        verdict=verdict,
        paper_fit=paper,
        lsq=lsq,
        posterior=posterior.summary,
        comparison=comparison,
        seconds=sum(clock.steps.values()),
        steps=clock.steps,
    )


def _auto_family(scene: Scene, measurements: Measurements, progress: Callable[[str], None]):
    """``--model auto``: the families of :data:`AUTO_FAMILIES` ranked by PSIS-LOO
    (:func:`brdf_infer.studies.compare.compare_families`), the first whose sampler
    diagnostics pass chosen (its ``table`` put in that order: the chosen family first)."""
    from brdf_infer.studies.compare import compare_families

    progress(f"model auto: comparing {', '.join(AUTO_FAMILIES)} by PSIS-LOO")
    result = compare_families(scene, measurements, list(AUTO_FAMILIES))
    usable = [row for row in result.table if not result.families[row["name"]].sampler_failures]
    if usable:
        first = usable[0]
        result.table = [first, *(row for row in result.table if row is not first)]
        progress(
            f"model auto: {first['name']} first (elpd_loo {first['elpd_loo']:.1f} ± "
            f"{first['se']:.1f}; the next by {_gap(result.table):.1f} ± "
            f"{result.table[1]['dse'] if len(result.table) > 1 else 0.0:.1f})"
        )
    return result


def _gap(table: list[dict[str, Any]]) -> float:
    """elpd_loo of the first row less the second's (0 with one row)."""
    return table[0]["elpd_loo"] - table[1]["elpd_loo"] if len(table) > 1 else 0.0


def _paper_fit(job: Job, implausible: list[Implausible]) -> dict[str, Any] | None:
    """Step 1: the paper fit (Eq. 7's regression; none for another family), checked."""
    from brdf_infer.verdict.plausibility import require_plausible

    scene, measurements = job.scene, job.measurements
    paper = None
    if job.paper_parameters:
        job.step(f"paper fit of scene '{scene.name}' ({len(measurements)} rows)")
        paper = paper_fit_summary(scene, measurements)
        implausible += fit_checks(scene, measurements, paper)
        require_plausible(implausible, job.settings.force)  # before the least squares' compile
    else:
        job.step(f"model {job.name}: no paper fit (it is Eq. 7's regression)")
    return paper


def _least_squares(
    job: Job, implausible: list[Implausible], paper: dict[str, Any] | None
) -> dict[str, Any]:
    """Step 2: the least-squares fit of every free parameter (its checks added to
    ``implausible``; ``paper``: step 1's fit, whose χ² it reports)."""
    from brdf_infer.model import family

    scene, measurements, settings, name = job.scene, job.measurements, job.settings, job.name
    job.step(f"least-squares fit of all free parameters of {name}")
    lsq = lsq_summary(
        scene,
        measurements,
        family(name, scene.model.fold, scene.model.constants),
        starts=settings.lsq_starts,
        seed=settings.seed,
        progress=job.progress,
        paper=None if paper is None else paper["params"],
    )
    implausible += fit_checks(scene, measurements, lsq)
    return lsq


def _write_fits(
    job: Job, implausible: list[Implausible], paper: dict[str, Any] | None, lsq: dict[str, Any]
) -> list[str]:
    """The plausibility checks passed (or forced: returned, one line each, each warned of),
    then the fits written."""
    from brdf_infer.verdict.plausibility import require_plausible

    out = job.out
    require_plausible(implausible, job.settings.force)  # before anything is written or sampled
    forced = [found.record for found in implausible]
    for line in forced:
        job.progress(f"warning: forced past a plausibility check: {line}")
    out.mkdir(parents=True, exist_ok=True)
    folder = RunFolder(out)
    if paper is not None:
        folder.write_json(FIT_PAPER_FILE, paper)
    folder.write_json(FIT_LSQ_FILE, lsq)
    return forced


def _posterior(job: Job, options: dict[str, Any], forced: list[str], lsq: dict[str, Any]):
    """Step 3: the scene's NUTS posterior into the run folder, its model check joined by the
    least-squares fit's (``lsq``)."""
    from brdf_infer.posterior import run_posterior

    settings = job.settings
    job.step(f"NUTS posterior ({settings.chains} chains x {settings.draws})")
    return run_posterior(
        job.scene,
        job.measurements,
        out=job.out,
        forced=forced,
        fit_checks=lsq.get("model_checks", []),
        **options,
    )


def _raytrace_study(job: Job, posterior) -> None:
    """Study: ray traces of the posterior (Sec. 6)."""
    from brdf_infer.studies.raytrace import write_traces

    scene = job.scene
    job.step(f"ray tracing series {scene.raytrace.series} (Sec. 6)")
    write_traces(job.out, scene, job.measurements, run_traces(scene, job.measurements, posterior))


def _report(job: Job, example: Path | None) -> tuple[Path, Verdict]:
    """Last step: the studies run (``studies.json``), the report and (``example``) the
    example copy."""
    from brdf_infer.report import write_example, write_report

    scene, out, studies = job.scene, job.out, job.studies
    RunFolder(out).write_studies(
        studies.requested(), not_run(scene, studies) if job.paper_parameters else []
    )
    job.step("report")
    report, verdict = write_report(out, progress=_silent)
    if example is not None:
        write_example(out, example)
    return report, verdict


def _check_studies(scene: Scene, instruments: list[str], sensitive: bool) -> None:
    """Refuse, before any work, an instrument study the scene's geometry cannot support, or
    a sensitivity study without a TIS."""
    from brdf_infer.scene import check_instrument
    from brdf_infer.studies.sensitivity import check_scene

    for instrument in instruments:
        check_instrument(scene, instrument, field="studies.instruments")
    if sensitive:
        check_scene(scene)
