"""Benchmark of the samplers: error against a long reference run, and ESS per second."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from brdf_infer._internal import arviz as az
from brdf_infer.model.params import PARAM_NAMES
from brdf_infer.posterior import Draws, build_posterior_model, run_emcee, run_nuts
from brdf_infer.scene import Scene


@dataclass(frozen=True)
class SamplerRow:
    sampler: str
    settings: str
    mean_error: float  # max over parameters of |mean − reference mean| / reference sd
    quantile_error: float  # the same for the 2.5 % and 97.5 % quantiles
    min_ess_bulk: float
    sampling_seconds: float
    setup_seconds: float  # emcee MAP search, compilation excluded
    compile_seconds: float


def _flat(draws: Draws) -> dict[str, np.ndarray]:
    return {name: np.asarray(draws.sites[name]).reshape(-1) for name in PARAM_NAMES}


def _row(label: str, settings: str, draws: Draws, reference: dict) -> SamplerRow:
    flat = _flat(draws)
    sd = {name: np.std(reference[name]) for name in PARAM_NAMES}
    mean_error = max(abs(flat[n].mean() - reference[n].mean()) / sd[n] for n in PARAM_NAMES)
    quantile_error = max(
        abs(np.quantile(flat[n], q) - np.quantile(reference[n], q)) / sd[n]
        for n in PARAM_NAMES
        for q in (0.025, 0.975)
    )
    ess = az.ess({name: np.asarray(draws.sites[name]) for name in PARAM_NAMES}, method="bulk")
    seconds = draws.seconds
    return SamplerRow(
        label,
        settings,
        float(mean_error),
        float(quantile_error),
        float(min(float(ess[name]) for name in PARAM_NAMES)),
        seconds["sampling"],
        seconds.get("initialise", 0.0),
        seconds["compile"],
    )


def sampler_rows(scene: Scene, quick: bool, progress=print) -> tuple[list[SamplerRow], str]:
    """Rows for NUTS and emcee at growing lengths, and a description of the reference run."""
    model = build_posterior_model(scene, scene.load_measurements())
    if quick:  # a long emcee run compiles in seconds; NUTS would take two compilations
        description = "emcee, 24 walkers x 6000 steps (1000 burn-in), seed 99"
        progress(f"  reference: {description}")
        reference = _flat(
            run_emcee(model, walkers=24, steps=6000, burn=1000, seed=99, progress=False)
        )
    else:
        description = "NUTS, 4 chains x 5000 draws after 1000 warmup, seed 99"
        progress(f"  reference: {description}")
        reference = _flat(
            run_nuts(model, chains=4, warmup=1000, draws=5000, seed=99, progress=False)
        )
    rows = []
    chains, warmup = (2, 500) if quick else (4, 1000)
    for draws in (250,) if quick else (250, 500, 1000):
        label = f"{chains} chains x ({warmup} warmup + {draws} draws)"
        progress(f"  NUTS {label}")
        result = run_nuts(model, chains=chains, warmup=warmup, draws=draws, progress=False)
        rows.append(_row("NUTS (dense mass)", label, result, reference))
    for steps in (2000,) if quick else (6000, 12000, 20000):
        progress(f"  emcee 24 walkers x {steps} steps")
        result = run_emcee(model, walkers=24, steps=steps, burn=steps // 5, progress=False)
        rows.append(_row("emcee", f"24 walkers x {steps} steps", result, reference))
    return rows, description
