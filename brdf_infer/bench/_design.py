"""Benchmark of ``brdf-infer design``: its expected posterior sd against NUTS refits.

What the design study estimates, E_y[sd(T | D, y)] after one new row at a setting x, has a
direct check: draw θ from the run's posterior, simulate the new row y from its conditional
predictive given the measured rows (:mod:`brdf_infer.design._estimate`, the same conditional
the estimate uses), append it to the measurements, sample the posterior again by NUTS, and
average the posterior variance of T over the replicates. Done for the best, the median and the
worst candidate of the grid, each replicate with its own simulated row; every refit runs
through one compiled NUTS program (the augmented data sets have one shape).

The run's own sd of T is itself an estimate from finitely many correlated draws (about 2 %
Monte Carlo error on the bundled scene), and a short refit's posterior sd scatters as much, so
absolute sds compare poorly when one row changes the sd by a few per cent. What design claims
is the *ratio* to today's sd; its check refits the measured rows alone with the same NUTS keys
(common random numbers) and compares the estimate's ``sd_ratio`` with the mean over replicates
of sd(with the row) / sd(without), whose Monte Carlo error (spread over √replicates) is
reported beside it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer.design import (
    Candidates,
    DesignOptions,
    candidate_measurements,
    design,
    load_design_run,
    predictive,
    target_values,
)
from brdf_infer.measurements import Measurements
from brdf_infer.params import PARAM_NAMES, Params
from brdf_infer.posterior import (
    NutsProgram,
    build_model_data,
    build_posterior_model,
    chain_keys,
)

HEADERS = [
    "candidate",
    "θi [deg]",
    "θs [deg]",
    "estimate: sd [%]",
    "refits: sd [%] (± MC)",
    "estimate: sd ratio",
    "refits: sd ratio (± MC)",
    "ESS",
    "replicates",
]


@dataclass(frozen=True)
class RefitSettings:
    """NUTS settings of the refits and replicates per candidate."""

    replicates: int = 4
    chains: int = 2
    warmup: int = 300
    draws: int = 300
    seed: int = 0
    design_draws: int = 1000
    simulations: int = 128


def _augmented(measurements: Measurements, rows: Measurements, log_values) -> Measurements:
    """``measurements`` with ``rows`` appended at the measured values exp(``log_values``)."""
    values = np.exp(np.asarray(log_values, float).reshape(-1))
    scale = values / rows.reflectance
    fields = {}
    for name in ("series", "sample", "theta_i_deg", "theta_s_deg"):
        fields[name] = np.concatenate([getattr(measurements, name), getattr(rows, name)])
    fields["reflectance"] = np.concatenate([measurements.reflectance, values])
    fields["reflectance_err"] = (
        None
        if measurements.reflectance_err is None
        else np.concatenate([measurements.reflectance_err, rows.reflectance_err * scale])
    )
    return Measurements(
        path=measurements.path, quantity=measurements.quantity, phi_s_deg=None, **fields
    )


def refit_check(
    run_dir: str | Path,
    target: str = "tis:70",
    series: str | None = None,
    settings: RefitSettings = RefitSettings(),
    progress=print,
) -> list[dict]:
    """Estimate against refit for the best, median and worst grid candidate (module docstring).

    Returns:
        One dict per candidate: ``pick``, the candidate's settings, ``estimate_sd``,
        ``estimate_ratio`` (design's ``sd_ratio``), ``refit_sd`` and its ``refit_mc``,
        ``refit_ratio`` (mean of sd with the row / sd of the measured rows alone, same keys)
        and its ``refit_ratio_mc``, ``ess``, ``replicates``, ``today_sd``, ``seconds``.
    """
    run = load_design_run(run_dir)
    options = DesignOptions(
        draws=settings.design_draws,
        simulations=settings.simulations,
        budget=1,
        seed=settings.seed,
    )
    result = design(run, target, options=options, series=series)
    ordered = result.candidates
    picks = {"best": 0, "median": len(ordered) // 2, "worst": len(ordered) - 1}
    scene, measurements = run.scene, run.measurements
    total = len(run.sites["brdf0"])
    keep = np.linspace(0, total - 1, min(settings.design_draws, total)).round().astype(int)
    keep = np.unique(keep)
    draws = {name: values[keep] for name, values in run.sites.items()}
    rng = np.random.default_rng(settings.seed)
    keys = [
        chain_keys(settings.seed + 100 * replicate, 1, settings.chains)[0]
        for replicate in range(settings.replicates)
    ]

    def variance(program: NutsProgram, data, replicate: int) -> float:
        sites = program.run(data, keys[replicate], settings.draws).sites
        params = Params(*(jnp.asarray(np.reshape(sites[n], -1)) for n in PARAM_NAMES))
        return float(np.var(target_values(result.target, params, scene)[:, 0]))

    today = NutsProgram(build_posterior_model(scene, measurements), warmup=settings.warmup)
    today_data = build_model_data(scene, measurements)
    today_variances = np.array(
        [variance(today, today_data, replicate) for replicate in range(settings.replicates)]
    )
    program = None
    rows = []
    for pick, index in picks.items():
        entry = ordered[index]
        candidate = Candidates(
            np.array([entry["series"]]),
            np.array([entry["theta_i_deg"]]),
            np.array([entry["theta_s_deg"]]),
            np.array([np.nan]),
        )
        conditional = predictive(run, candidate, draws)
        sd = np.sqrt(
            np.asarray(conditional.own[:, 0])
            + np.sum(np.asarray(conditional.loading[:, 0]) ** 2, 1)
        )
        new_row = candidate_measurements(candidate, measurements)
        start = time.perf_counter()
        variances = []
        for replicate in range(settings.replicates):
            s = int(rng.integers(len(keep)))
            log_value = float(conditional.mean[s, 0]) + sd[s] * float(rng.standard_normal())
            augmented = _augmented(measurements, new_row, log_value)
            if program is None:
                program = NutsProgram(
                    build_posterior_model(scene, augmented), warmup=settings.warmup
                )
            variances.append(variance(program, build_model_data(scene, augmented), replicate))
            progress(f"  design refit {pick} {replicate + 1}/{settings.replicates}")
        variances = np.array(variances)
        ratios = np.sqrt(variances / today_variances)
        spread = settings.replicates > 1
        rows.append(
            {
                "pick": pick,
                **{k: entry[k] for k in ("theta_i_deg", "theta_s_deg", "series")},
                "estimate_sd": entry["expected_sd"],
                "estimate_ratio": entry["sd_ratio"],
                "refit_sd": float(np.sqrt(np.mean(variances))),
                "refit_mc": float(
                    0.5
                    * np.std(variances, ddof=1)
                    / np.sqrt(len(variances))
                    / np.sqrt(np.mean(variances))
                )
                if spread
                else float("nan"),
                "refit_ratio": float(np.mean(ratios)),
                "refit_ratio_mc": float(np.std(ratios, ddof=1) / np.sqrt(len(ratios)))
                if spread
                else float("nan"),
                "ess": entry["ess"],
                "replicates": settings.replicates,
                "today_sd": result.current["sd"],
                "seconds": time.perf_counter() - start,
            }
        )
    jax.clear_caches()
    return rows


def refit_rows(rows: list[dict], scale: float = 100.0) -> list[list[str]]:
    """Markdown table rows of :func:`refit_check` (sd in per cent of the target)."""
    return [
        [
            r["pick"],
            f"{r['theta_i_deg']:g}",
            f"{r['theta_s_deg']:g}",
            f"{scale * r['estimate_sd']:.3f}",
            f"{scale * r['refit_sd']:.3f} ± {scale * r['refit_mc']:.3f}",
            f"{r['estimate_ratio']:.3f}",
            f"{r['refit_ratio']:.3f} ± {r['refit_ratio_mc']:.3f}",
            f"{r['ess']:.0f}",
            str(r["replicates"]),
        ]
        for r in rows
    ]
