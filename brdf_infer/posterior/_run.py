"""``run_posterior``: scene → model → sampler → InferenceData, diagnostics, bands → files."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from brdf_infer._arviz import az
from brdf_infer.errors import BadInputError
from brdf_infer.measurements import Measurements
from brdf_infer.params import PARAM_NAMES
from brdf_infer.posterior._bands import compute_bands, draws_params
from brdf_infer.posterior._model import build_posterior_model
from brdf_infer.posterior._results import diagnostics, inference_data, write_results
from brdf_infer.posterior._samplers import run_emcee, run_nuts
from brdf_infer.scene import Scene

CHECKPOINT_FILE = "emcee_checkpoint.npz"


@dataclass(frozen=True)
class PosteriorRun:
    """Everything a posterior run produced (also written to ``out``)."""

    idata: az.InferenceData
    summary: dict[str, Any]
    bands: dict[str, Any]
    out: Path | None


def run_posterior(
    scene: Scene,
    measurements: Measurements,
    *,
    sampler: str = "nuts",
    chains: int = 4,
    draws: int = 1000,
    warmup: int = 1000,
    walkers: int | None = None,
    steps: int = 20000,
    seed: int = 0,
    out: Path | None = None,
    resume: bool = False,
    angle_error: bool = False,
    hierarchical: bool = False,
    progress: bool | None = None,
) -> PosteriorRun:
    """Sample the scene's posterior and write posterior.nc, summary.json, bands.json.

    Args:
        sampler: ``nuts`` or ``emcee``.
        chains, draws, warmup: NUTS settings (emcee: ``warmup`` is the burn-in in steps).
        walkers, steps: emcee settings (walkers default: max(24, 2 × dimension)).
        seed: random seed of the sampler.
        out: output directory (nothing written when None; emcee then keeps no checkpoint).
        resume: continue an interrupted emcee run from ``out``'s checkpoint.
        angle_error: propagate the scene's angle uncertainty (also on when the scene's
            ``errors.propagate_angles`` is).
        hierarchical: per-sample offsets instead of the spread term (also on when the scene's
            ``errors.hierarchical`` is).
        progress: progress bar on stderr (default: when stderr is a terminal).
    """
    if sampler not in ("nuts", "emcee"):
        raise BadInputError(f"unknown sampler {sampler!r} (nuts, emcee)", field="--sampler")
    for name, value in (
        ("chains", chains),
        ("draws", draws),
        ("walkers", walkers),
        ("steps", steps),
    ):
        if value is not None and value < 1:
            raise BadInputError(f"must be at least 1, got {value}", field=f"--{name}")
    if warmup < 0:
        raise BadInputError(f"must be >= 0, got {warmup}", field="--warmup")
    if resume and sampler != "emcee":
        raise BadInputError(
            "--resume continues an emcee run; NUTS runs are not checkpointed", field="--resume"
        )
    started = time.perf_counter()
    angle_error = angle_error or scene.errors.propagate_angles
    hierarchical = hierarchical or scene.errors.hierarchical
    model = build_posterior_model(
        scene, measurements, angle_error=angle_error, hierarchical=hierarchical
    )
    if sampler == "nuts":
        result = run_nuts(
            model, chains=chains, warmup=warmup, draws=draws, seed=seed, progress=progress
        )
    else:
        checkpoint = None if out is None else out / CHECKPOINT_FILE
        if out is not None:
            out.mkdir(parents=True, exist_ok=True)
        result = run_emcee(
            model,
            walkers=walkers,
            steps=steps,
            burn=warmup,
            seed=seed,
            checkpoint=checkpoint,
            resume=resume,
            progress=progress,
        )
    idata = inference_data(model, result, seed)
    params = draws_params(result.sites)
    bands = compute_bands(
        params, scene.output_theta_i_deg, scene.model.fold, scene.model.constants, scene.makes_tis
    )
    checks = diagnostics(idata, result)
    tis_70 = (
        {key: bands["tis"][key][70] for key in ("median", "lo68", "hi68", "lo95", "hi95")}
        if "tis" in bands
        else None
    )
    summary = {
        "scene": scene.name,
        "sampler": result.sampler,
        "settings": result.settings,
        "options": {
            "angle_error": angle_error,
            "hierarchical": hierarchical,
            "anchors": None if model.anchors is None else model.anchors.tolist(),
        },
        "n_points": len(measurements),
        "median": {name: float(np.median(getattr(params, name))) for name in PARAM_NAMES},
        "diagnostics": checks,
        "tis_70deg": tis_70,
        "pi_brdf0": {key: bands["pi_brdf0"][key] for key in ("median", "lo95", "hi95")},
        "seconds": {**result.seconds, "total": time.perf_counter() - started},
    }
    if out is not None:
        write_results(out, idata, summary, bands)
        if sampler == "emcee":
            (out / CHECKPOINT_FILE).unlink(missing_ok=True)
    return PosteriorRun(idata, summary, bands, out)
