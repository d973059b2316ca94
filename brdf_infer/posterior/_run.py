"""``run_posterior``: scene → model → sampler → InferenceData, diagnostics, bands → files."""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import time
import tomllib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from brdf_infer._internal import arviz as az
from brdf_infer._internal.outlock import writing
from brdf_infer._internal.precision import ensure_float64
from brdf_infer._internal.step_clock import StepClock
from brdf_infer.errors import BadInputError
from brdf_infer.model import check_family_name
from brdf_infer.model.error_model import ERROR_MODELS, ErrorSettings, calibration_group_names
from brdf_infer.model.params import PARAM_NAMES
from brdf_infer.posterior._answer import answer_records
from brdf_infer.posterior._bands import (
    draws_physical,
    interval95,
    posterior_bands,
)
from brdf_infer.posterior._campaigns import campaign_records
from brdf_infer.posterior._laplace import laplace_draws
from brdf_infer.posterior._loo import (
    ExactTerm,
    LeaveOneOut,
    psis_loo,
    relative_efficiency,
    uniformity_p_value,
)
from brdf_infer.posterior._loo_refit import exact_loo_rows
from brdf_infer.posterior._memory import check_memory
from brdf_infer.posterior._model import NOISE_SITES, PosteriorModel, build_posterior_model
from brdf_infer.posterior._model_check import model_check, posterior_checks
from brdf_infer.posterior._potential import FlatPotential
from brdf_infer.posterior._results import (
    diagnostics,
    factor_columns,
    inference_data,
    loo_sites,
    loo_terms,
    store_measurements,
    write_results,
)
from brdf_infer.posterior._samplers import (
    Draws,
    Refused,
    emcee_settings,
    load_checkpoint,
    run_emcee,
    run_nuts,
)
from brdf_infer.posterior._targets import (
    NEW_PART_EFFECT,
    SAMPLE_EFFECT,
    chosen_target,
    latent_effect_draws,
    new_part_draws,
    store_calibration_effects,
    store_effects,
    target_log_factor,
)
from brdf_infer.runs.folder import CHECKPOINT_FILE
from brdf_infer.runs.records import Bands, PosteriorSummary
from brdf_infer.scene import Scene, check_instrument, load_scene, parse_scene
from brdf_infer.scene.settings import PosteriorSettings, resolved_sampler
from brdf_infer.tables.measurements import Measurements
from brdf_infer.verdict import posterior_verdict


@dataclass(frozen=True)
class PosteriorRun:
    """Everything a posterior run produced (also written to ``out``)."""

    idata: az.InferenceData
    summary: PosteriorSummary  # summary.json
    bands: Bands  # bands.json
    out: Path | None


def with_error_model(scene: Scene, error_model: str | None) -> Scene:
    """``scene`` with its ``errors.model`` replaced (None: unchanged)."""
    if error_model is None or error_model == scene.errors.model:
        return scene
    if error_model not in ERROR_MODELS:
        raise BadInputError(
            f"unknown error model {error_model!r} ({', '.join(ERROR_MODELS)})",
            field="error_model",
        )
    return dataclasses.replace(scene, errors=dataclasses.replace(scene.errors, model=error_model))


def run_scene(attrs) -> Scene:
    """The scene a posterior run sampled, from its ``posterior`` group's attributes: the scene
    text recorded with the run (``scene_toml``; a run without it: the scene file as it is now),
    read as if from its file (relative paths as there) but without reading the files it names
    (the run keeps its rows, :func:`~brdf_infer.posterior._results.run_measurements`), with the
    run's error model as recorded (``error_model``: ``--error-model`` may have changed it, and
    a τ prior from another run is kept there) and its instrument model.

    Raises:
        BadInputError: the recorded text no longer reads as a scene.
    """
    path = Path(str(attrs.get("scene_file", "lya")))
    recorded = json.loads(attrs.get("error_model", "{}"))
    if "scene_toml" not in attrs:
        scene = load_scene(path)
    else:
        try:
            document = tomllib.loads(str(attrs["scene_toml"]))
        except tomllib.TOMLDecodeError as error:
            raise BadInputError(f"the run's scene text: invalid TOML: {error}", file=path) from None
        if isinstance(document.get("errors"), dict):  # its τ prior is in the record
            document["errors"].pop("sample_sd_from", None)
        scene = parse_scene(document, path)
        scene = dataclasses.replace(scene, errors=recorded_errors(scene.errors, recorded))
    instrument = str(attrs.get("instrument", scene.instrument.model))
    if instrument != scene.instrument.model:
        scene = check_instrument(scene, instrument, field="instrument")
    return with_error_model(scene, recorded.get("model"))


def recorded_errors(errors: ErrorSettings, recorded: dict) -> ErrorSettings:
    """``errors`` with every setting a run recorded (``ErrorSettings.describe``) put back;
    a setting the record lacks (an older run) stays as parsed."""
    fields = ErrorSettings.__dataclass_fields__
    values = {key: value for key, value in recorded.items() if key in fields}
    kde = values.get("sample_sd_log_kde")
    if kde is not None:
        values["sample_sd_log_kde"] = tuple(tuple(map(float, part)) for part in kde)
    return dataclasses.replace(errors, **values)


def build_model(
    scene: Scene, measurements: Measurements, name: str | None = None
) -> PosteriorModel:
    """The posterior model of ``scene`` under the family ``name`` (default: the scene's
    ``[model] family``), with the scene's fold and constants.

    Raises:
        BadInputError: an unknown family (field ``model``), or latent angles with a family
            other than ``strumik2024``.
    """
    name = scene.model.family if name is None else name
    check_family_name(name)
    return build_posterior_model(scene, measurements, scene.family(name))


def model_name(model: PosteriorModel) -> str:
    """The family a posterior model samples."""
    return model.family.name


def run_fingerprint(model: PosteriorModel, measurements: Measurements) -> dict[str, str]:
    """Hashes of what a run samples: the scene text, the measurement rows, the model options."""

    def digest(data: bytes) -> str:
        return hashlib.sha256(data).hexdigest()[:16]

    rows = b"".join(
        np.ascontiguousarray(array).tobytes()
        for array in (
            measurements.series.astype(str),
            measurements.sample.astype(str),
            measurements.theta_i_deg,
            measurements.theta_s_deg,
            measurements.reflectance,
            np.zeros(0) if measurements.reflectance_err is None else measurements.reflectance_err,
            *(() if measurements.phi_s_deg is None else (measurements.phi_s_deg,)),
        )
    )
    scene = model.scene
    options = {
        "errors": scene.errors.describe(),
        "fold": scene.model.fold,
        "constants": scene.model.constants._asdict(),
        "priors": {name: dataclasses.asdict(prior) for name, prior in scene.priors.items()},
        "reparametrised": model.whiten,
        "family": model_name(model),
    }
    return {
        "scene": digest(scene.path.read_bytes()),
        "measurements": digest(rows),
        "model options": digest(json.dumps(options, sort_keys=True, default=str).encode()),
    }


def predictive_checks(
    loo: LeaveOneOut,
    measurements: Measurements | None = None,
    exact: dict[int, ExactTerm] | None = None,
) -> dict:
    """PSIS-LOO (elpd with its standard error, p_loo, every row's Pareto k, the largest, the
    number of rows above ``pareto_k_limit`` (:func:`~brdf_infer.verdict.pareto_k_limit` of the
    draws read) not refitted and, given ``measurements``, those rows by name) and the LOO-PIT
    of every row with a Kolmogorov–Smirnov test of its uniformity (:func:`psis_loo`);
    the rows of ``exact`` (:func:`~brdf_infer.posterior._loo_refit.exact_loo_rows`) by refit,
    listed under ``loo_refit_rows``."""
    exact = exact or {}
    loo = loo.with_exact(exact)
    pareto_k = loo.pareto_k
    high = high_k_rows(measurements, pareto_k, loo.limit) if measurements is not None else None
    named = {}
    if high is not None:
        named["pareto_k_rows"] = [row for row in high if row["row"] not in exact]
        named["loo_refit_rows"] = [
            {
                **row,
                "elpd_exact": exact[row["row"]].elpd,
                "elpd_exact_mcse": exact[row["row"]].mcse,
            }
            for row in high
            if row["row"] in exact
        ]
    mcse = None if loo.mcse_i is None else float(np.sqrt(np.sum(loo.mcse_i**2)))
    return {
        **named,
        "elpd_loo": loo.elpd_loo,
        "se": loo.se,
        "elpd_loo_mcse": mcse,  # Monte Carlo standard error (independent rows' terms)
        "p_loo": loo.p_loo,
        "pareto_k_max": float(np.max(pareto_k)),
        "pareto_k_limit": loo.limit,
        "pareto_k_high": sum(
            1 for row in np.flatnonzero(pareto_k > loo.limit) if int(row) not in exact
        ),
        "pareto_k": pareto_k.tolist(),  # per row, for the report
        "loo_pit": loo.pit.tolist(),
        "loo_pit_ks_p": uniformity_p_value(loo.pit),
    }


def high_k_rows(measurements: Measurements, pareto_k: np.ndarray, limit: float) -> list[dict]:
    """The rows whose Pareto k exceeds ``limit``, each with its index, series, sample, angles
    [deg] and k."""
    rows = []
    for index in np.flatnonzero(pareto_k > limit):
        phi = None if measurements.phi_s_deg is None else float(measurements.phi_s_deg[index])
        rows.append(
            {
                "row": int(index),
                "series": str(measurements.series[index]),
                "sample": str(measurements.sample[index]),
                "theta_i_deg": float(measurements.theta_i_deg[index]),
                "theta_s_deg": float(measurements.theta_s_deg[index]),
                **({} if phi is None or not np.isfinite(phi) else {"phi_s_deg": phi}),
                "k": float(pareto_k[index]),
            }
        )
    return rows


def run_posterior(
    scene: Scene,
    measurements: Measurements,
    settings: PosteriorSettings | None = None,
    *,
    out: Path | None = None,
    resume: bool = False,
    error_model: str | None = None,
    model: str | None = None,
    progress: bool | None = None,
    announce: Callable[[str], None] | None = None,
    forced: Sequence[str] = (),
    refit: bool = True,
    fit_checks: Sequence[dict[str, Any]] = (),
    **sampler_settings: Any,
) -> PosteriorRun:
    """Sample the scene's posterior and write posterior.nc, summary.json, bands.json.

    Args:
        settings: how to sample (:class:`~brdf_infer.scene.settings.PosteriorSettings`: sampler,
            chains, draws, warmup, walkers, steps, seed, target_accept; its defaults are
            ``brdf-infer posterior``'s).
        out: output directory (nothing written when None; emcee then keeps no checkpoint).
        resume: continue an interrupted emcee run from ``out``'s checkpoint.
        error_model: override the scene's ``errors.model`` (``generative`` or ``spread``).
        model: the BRDF family to sample (default: the scene's ``[model] family``); every
            family writes the same files (its physical parameters in the posterior, its
            bands; π·BRDF0 for ``strumik2024`` only).
        progress: progress bar on stderr (default: when stderr is a terminal).
        announce: called with the run in one line, its settings checked, before sampling.
        forced: the plausibility checks (:mod:`brdf_infer.verdict.plausibility`) the caller
            went past with ``--force``, one line each: they open the run's verdict.
        fit_checks: the least-squares fit's checks of the model against the rows
            (:meth:`brdf_infer.fit.quality.FitQuality.model_checks`), which join the run's own
            in its ``model_check`` record (:mod:`._model_check`).
        refit: sample an error-model variant anew where reweighting to it is unreliable
            (:mod:`brdf_infer.posterior._width`), and a row of Pareto k > 0.7 without it for
            its exact leave-one-out term (:mod:`brdf_infer.posterior._loo_refit`); False:
            neither (studies, batch): such a variant is reported unreliable, such a row stays
            a failure of the verdict.
        **sampler_settings: fields of :class:`~brdf_infer.scene.settings.PosteriorSettings` in
            place of ``settings``' (``run_posterior(scene, rows, draws=500)``).

    Raises:
        BadInputError: a setting out of range or unknown, or a checkpoint that this run did
            not write.
    """
    ensure_float64()
    settings = posterior_settings(settings, sampler_settings)
    if resume and settings.sampler != "emcee":
        raise BadInputError(
            "--resume continues an emcee run; NUTS runs are not checkpointed", field="resume"
        )
    claim = contextlib.nullcontext() if out is None else writing(out, "posterior")
    with claim:  # one writer per folder; an interrupted run leaves it marked incomplete
        started = time.perf_counter()
        scene = with_error_model(scene, error_model)
        name = scene.model.family if model is None else model
        model = build_model(scene, measurements, name)
        what = _describe(model, measurements, settings, out, resume)
        _check_memory(model, measurements, settings)
        if announce is not None:
            announce(f"posterior of scene '{scene.name}' ({name}) with {settings.sampler}: {what}")
        result = _sample(
            model,
            measurements,
            settings,
            out=out,
            resume=resume,
            progress=progress,
            announce=announce,
        )
        return complete_run(
            model,
            measurements,
            result,
            settings.seed,
            out,
            started,
            forced=forced,
            refit=refit,
            fit_checks=fit_checks,
        )


def posterior_settings(
    settings: PosteriorSettings | None, fields: dict[str, Any]
) -> PosteriorSettings:
    """``settings`` with ``fields`` in place of its own (every one checked; a field the
    record lacks is refused by name), or the record of ``fields`` alone."""
    known = {field.name for field in dataclasses.fields(PosteriorSettings)}
    for name in fields:
        if name not in known:
            raise BadInputError(
                f"not a posterior setting (known: {', '.join(sorted(known))})", field=name
            )
    if settings is None:
        return PosteriorSettings(**fields)
    values = {field.name: getattr(settings, field.name) for field in dataclasses.fields(settings)}
    if "warmup" not in fields and settings.warmup == PosteriorSettings(settings.sampler).warmup:
        values["warmup"] = None  # the sampler's default, that of a new sampler if one is given
    return PosteriorSettings(**{**values, **fields})


def _check_memory(model, measurements, settings: PosteriorSettings) -> None:
    """:func:`~brdf_infer.posterior._memory.check_memory` of the run's rows and draws (emcee:
    walkers × steps, an upper bound)."""
    if settings.sampler != "emcee":
        total = settings.chains * settings.draws
    else:
        total = (settings.walkers or 24) * settings.steps
    columns = factor_columns(model.data.noise)
    check_memory(len(measurements), total, settings.chains, columns, measurements.path)


def _describe(model, measurements, settings: PosteriorSettings, out, resume) -> str:
    """The run's sampler settings in words (:func:`run_posterior`'s ``announce``); an emcee
    checkpoint to resume is checked first."""
    warmup = settings.warmup
    nuts = f"{settings.chains} chains x ({warmup} warmup + {settings.draws} draws)"
    sampler = resolved_sampler(settings.sampler, len(measurements))
    if sampler == "nuts":
        return nuts
    if sampler == "laplace":
        proposals = settings.chains * settings.draws
        return f"Laplace + PSIS, {proposals} proposals (NUTS {nuts} where refused)"
    dimension = FlatPotential(model).dimension
    emcee = emcee_settings(dimension, settings.walkers, settings.steps, warmup, settings.seed)
    if resume:
        identity = {**run_fingerprint(model, measurements), "dimension": str(dimension)}
        load_checkpoint(None if out is None else out / CHECKPOINT_FILE, emcee, identity)
    return f"{emcee['walkers']} walkers x {settings.steps} steps ({warmup} burn-in)"


def _sample(
    model, measurements, settings: PosteriorSettings, *, out, resume, progress, announce=None
) -> Draws:
    """The draws of :func:`run_posterior`'s sampler (``auto`` resolved by the rows; Laplace
    falls back to NUTS where its diagnostics refuse it, the reason in ``extra`` and said to
    ``announce``; emcee: checkpointed in ``out``)."""
    sampler = resolved_sampler(settings.sampler, len(measurements))
    refusal = None
    if sampler == "laplace":
        drawn = laplace_draws(
            model, chains=settings.chains, draws=settings.draws, seed=settings.seed
        )
        if not isinstance(drawn, Refused):
            return drawn
        refusal = drawn.reason
        if announce is not None:
            announce(f"Laplace + PSIS refused ({refusal}); sampling with NUTS")
    if sampler in ("nuts", "laplace"):
        result = run_nuts(
            model,
            chains=settings.chains,
            warmup=settings.warmup,
            draws=settings.draws,
            seed=settings.seed,
            target_accept=settings.target_accept,
            progress=progress,
        )
        if refusal is not None:
            result = dataclasses.replace(result, extra={**result.extra, "laplace_refused": refusal})
        return result
    checkpoint = None if out is None else out / CHECKPOINT_FILE
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    return run_emcee(
        model,
        walkers=settings.walkers,
        steps=settings.steps,
        burn=settings.warmup,
        seed=settings.seed,
        checkpoint=checkpoint,
        resume=resume,
        fingerprint=run_fingerprint(model, measurements),
        progress=progress,
    )


def _tis_70(bands: Bands) -> dict | None:
    """TIS(70°)'s median, 68 % and 95 % intervals from the bands (None: no TIS band)."""
    if "tis" not in bands:
        return None
    at = bands["tis"]["theta_i_deg"].index(70.0)
    return {key: bands["tis"][key][at] for key in ("median", "lo68", "hi68", "lo95", "hi95")}


def _loo_terms(model: PosteriorModel, result: Draws, rows: int):
    """The leave-one-out terms (log p, P) of the draws PSIS-LOO reads (every draw of a small
    run; ``LOO_VALUES``) and the thinning factor, draws over the draws read."""
    sites, thinning = loo_sites(result.sites, rows)
    log_lik, cdf = loo_terms(model, sites)
    return log_lik, cdf, thinning


def complete_run(
    model: PosteriorModel,
    measurements: Measurements,
    result: Draws,
    seed: int,
    out: Path | None,
    started: float,
    *,
    forced: Sequence[str] = (),
    refit: bool = True,
    fit_checks: Sequence[dict[str, Any]] = (),
) -> PosteriorRun:
    """From a sampler's draws to the run: InferenceData, PSIS-LOO and LOO-PIT, bands,
    diagnostics, the model check (:mod:`._model_check`; ``fit_checks`` as
    :func:`run_posterior`'s), the summary and its verdict (:mod:`brdf_infer.verdict`;
    ``forced``: the plausibility checks the run went past), written to ``out`` (when given)
    atomically; ``started``: the ``time.perf_counter()`` at the start of the run (its total
    time). The bands, ``tis_70deg`` and ``pi_brdf0`` describe the scene's ``[outputs]
    target`` (:mod:`._targets`); ``targets`` holds all three."""
    scene, name = model.scene, model.family.name
    clock = StepClock()
    log_lik, cdf, thinning = _loo_terms(model, result, len(measurements))
    clock.lap("loo_terms")
    idata = inference_data(model, result, seed, log_lik if thinning == 1 else None)
    store_measurements(idata, measurements)
    clock.lap("inference_data")
    theta_i_band = scene.band_theta_i_deg(measurements)
    member = model.family
    physical = draws_physical(result.sites, member)
    with_tis = scene.outputs.tis and member.hemispheric(scene.model.out_of_plane)
    target = chosen_target(scene.outputs.target, len(model.sample_names))
    sample_effects, calibration_effects = latent_effect_draws(model, result.sites, seed + 23)
    effects = {
        SAMPLE_EFFECT: sample_effects,
        NEW_PART_EFFECT: new_part_draws(model, result.sites, seed + 29),
    }
    store_effects(idata, effects, model.sample_names, target)
    # stored before the relative efficiency, which reads every variable of the posterior group
    store_calibration_effects(
        idata, calibration_effects, calibration_group_names(scene.errors, measurements)
    )
    factor = target_log_factor(target, *effects.values(), model.sample_names)
    products = model.products  # the same parameters as the family's
    bands = posterior_bands(products, products.scaled(physical, factor), theta_i_band, with_tis)
    bands["target"] = target
    parameters = member.parameters
    # the scene's [priors] (which may fix a parameter) are Eq. (7)'s; other families use their own
    fixed = tuple(n for n in PARAM_NAMES if n not in scene.free_parameters)
    fixed = fixed if member.paper_parameters else ()
    medians = {n: float(np.median(v)) for n, v in physical.items()}
    pi_brdf0 = None
    if "pi_brdf0" in bands:
        pi_brdf0 = {key: bands["pi_brdf0"][key] for key in ("median", "lo95", "hi95")}
    clock.lap("bands")
    checks = diagnostics(idata, result, parameters, fixed)
    clock.lap("diagnostics")
    reff = relative_efficiency(idata.posterior, thinning)
    loo = psis_loo(log_lik, cdf, reff)
    exact = exact_loo_rows(model, result, loo.pareto_k, loo.limit) if refit else {}
    clock.lap("loo")
    answer = answer_records(
        model,
        measurements,
        result,
        theta_i_band,
        with_tis,
        seed,
        refit,
        loo.elpd_i,
        reff,
        effects,
        target,
    )
    clock.lap("answer")
    predictive = predictive_checks(loo, measurements, exact)
    pit = np.asarray(predictive["loo_pit"])
    pooled, pooled_checks = campaign_records(
        model, measurements, calibration_effects, loo.with_exact(exact).elpd_i, pit
    )
    own_checks = [*posterior_checks(model, measurements, pit, result.sites), *pooled_checks]
    summary = {
        "scene": scene.name,
        "model": name,
        "instrument": scene.instrument.model,
        "sampler": result.sampler,
        "settings": result.settings,
        "error_model": scene.errors.describe(),
        "options": {"reparametrised": model.whiten},
        "n_points": len(measurements),
        "fold": bands["fold"],  # Eq. (10) in the bands and TIS (the scene's [outputs] fold)
        "likelihood_fold": member.fold,  # Eq. (10) in what the rows measured ([model] fold)
        "median": medians,
        "units": dict(member.units),
        "noise": {
            site: interval95(result.sites[site]) for site in NOISE_SITES if site in result.sites
        },
        "diagnostics": checks,
        "predictive": predictive,
        "model_check": model_check([*fit_checks, *own_checks], scene, measurements),
        **pooled,  # calibration_effects, and campaigns for a pooled scene
        "target": target,  # what tis_70deg, pi_brdf0 and the bands describe
        "tis_70deg": _tis_70(bands),
        "pi_brdf0": pi_brdf0,
        **answer,  # width, learned, reference
        "seconds": dict(result.seconds),
        "forced": list(forced),
        # what reading a .BSDF table left out, by rule (brdf_infer.tables.screening); a CSV: none
        **({} if measurements.screening is None else {"table": measurements.screening.as_json()}),
        "fingerprint": run_fingerprint(model, measurements),  # what ran: for a resume
    }
    summary["verdict"] = posterior_verdict(summary, bands, theta_i_band, forced).as_json()
    clock.lap("predictive")
    summary["seconds"]["after_sampling"] = clock.steps  # the files are written after this
    summary["seconds"]["total"] = time.perf_counter() - started
    if out is not None:
        write_results(out, idata, summary, bands)
        if result.sampler == "emcee":
            (out / CHECKPOINT_FILE).unlink(missing_ok=True)
    return PosteriorRun(idata, summary, bands, out)
