"""The benchmark's power of the model checks: how often each check of a run fails on data
simulated with a known fault, and how often on data without one (its false alarms).

A run's ``model_check`` record (:mod:`brdf_infer.posterior._model_check`, the least-squares
fit's :meth:`brdf_infer.fit.quality.FitQuality.model_checks`) says ``ok`` when no check fails at
p < 0.001; what that ``ok`` is worth is the share of faulty data sets the checks let through.
Here data sets of the bundled scene's layout (``lya``, 42 rows) are drawn from the scene's
generative error model at a truth (:func:`simulate`: the error model's definition written out,
as ``tests/test_fit_quality.py`` does: a rotation error per (series, sample, θi) setting and a
camera error per row moving the angles, each row's own sd, the learned repeatability and the
sample effects at the bundled posterior's medians, one calibration factor per series at the
scene's 6.5 %), with one of the :data:`FAULTS` planted, and each is fitted as a run fits it:
least squares (:func:`brdf_infer.workflow.lsq_summary`, its ``model_checks``) and a short NUTS
posterior whose draws and leave-one-out predictive give the posterior's checks
(:func:`brdf_infer.posterior._model_check.posterior_checks`).

Replicate i of every fault draws the same noise (the generator seeded by (seed, i), the
fault's own scatter drawn last) and the same NUTS keys, so the faults differ only in what was
planted; every fit of one scene shares one compiled NUTS program.
"""

from __future__ import annotations

import math
import re
import statistics
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from benchmarks._tables import markdown_table
from brdf_infer.model.params import UV_PAPER, Params
from brdf_infer.scene import Scene

# the bundled posterior's medians of the learned noise scales [ln R] (tests/test_fit_quality.py)
POSTERIOR_SCALES = {"repeatability": 0.022, "sample": 0.027}
NUTS = {"chains": 2, "warmup": 300, "draws": 300}  # each replicate's posterior run
REPLICATES = 30  # per fault: the full benchmark's
QUICK_REPLICATES = 4  # per fault: bench --quick
REFF = 1.0  # the relative efficiency PSIS-LOO's smoothing is given
SERIES_FACTOR = 1.3  # series II's rows × this
TREND_FACTOR = 1.4  # exp(d) of the θs trend d·(θs − mean)/range
ALPHA_LOW = 3.6  # α of the α fault (uv-paper's 4.5, 20 % low)
CHECK_ORDER = ("fit_repeatability", "fit_chi2", "fit_residual_trend", "loo_pit", "residual_trend")
CHECK_ORDER += ("at_bound",)
_NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:e[+-]?\d+)?")


@dataclass(frozen=True)
class Fault:
    """One planted fault: its ``name`` and ``size`` in words, the ``truth`` the data are drawn
    at, the ``scene`` that fits them, a further lognormal ``scatter`` per row [ln R] and a
    ``shift`` of ln R (``series_II``: series II's rows by ln 1.3; ``theta_s``: the θs trend)."""

    name: str
    size: str
    truth: str = "uv-paper"  # or "alpha-low"
    scene: str = "lya"
    scatter: float = 0.0
    shift: str | None = None


FAULTS = (
    Fault("none", "—"),
    Fault("α 20 % low, fitted with α = 4.5 fixed", "α = 3.6", "alpha-low", "lya-fixed"),
    Fault("random shape error", "15 % rms per row", scatter=0.15),
    Fault("random shape error", "28 % rms per row", scatter=0.28),
    Fault("series offset", "series II × 1.3", shift="series_II"),
    Fault("θs trend", "× 1.4 across the θs range", shift="theta_s"),
)


def alpha_fault_truth() -> Params:
    """uv-paper with α = 3.6, b2 = a2·90^(1+α) and b3 kept (the prior's coordinates; as
    ``tests/test_fit_quality.py::_alpha_fault_truth``)."""
    shift = 90.0 ** (UV_PAPER.alpha - ALPHA_LOW)
    return UV_PAPER._replace(alpha=ALPHA_LOW, a2=UV_PAPER.a2 * shift, a3=UV_PAPER.a3 * shift)


def fault_truth(fault: Fault) -> Params:
    """The parameters ``fault``'s data are drawn at."""
    return alpha_fault_truth() if fault.truth == "alpha-low" else UV_PAPER


def fault_shift(fault: Fault, rows) -> np.ndarray:
    """The fault's deterministic change of every row's ln R (zeros without one)."""
    shift = np.zeros(len(rows))
    if fault.shift == "series_II":
        shift[np.asarray(rows.series) == "II"] = math.log(SERIES_FACTOR)
    elif fault.shift == "theta_s":
        theta_s = np.asarray(rows.theta_s_deg, float)
        span = float(np.ptp(theta_s))
        shift = math.log(TREND_FACTOR) * (theta_s - theta_s.mean()) / span
    elif fault.shift is not None:
        raise ValueError(f"unknown shift {fault.shift!r}")
    return shift


def simulate(scene: Scene, rows, fault: Fault, rng: np.random.Generator, noise: bool = True):
    """Rows of ``rows``' layout drawn from ``scene``'s generative error model at the fault's
    truth, the fault planted: the angles moved by a rotation error per (series, sample, θi)
    setting (θi + ε, θs + ε: the camera follows) and a camera error per row (θs + η), ln R of
    Eq. (7) at the moved angles plus the fault's shift (at the nominal θs), then each row's
    own sd (its ± over √12 for series I), the repeatability, one effect per physical sample and
    one calibration factor per series, and last the fault's scatter. ``noise=False``: every
    random term zero (the noise-free part)."""
    from brdf_infer.studies.synthetic import synthetic_measurements

    errors = scene.errors
    on = 1.0 if noise else 0.0
    settings = list(zip(rows.series, rows.sample, rows.theta_i_deg, strict=True))
    rotation = {key: rng.normal(0.0, errors.rotation_deg) for key in dict.fromkeys(settings)}
    epsilon = on * np.array([rotation[key] for key in settings])
    camera = on * rng.normal(0.0, errors.camera_deg, len(rows))
    moved = replace(
        rows,
        theta_i_deg=rows.theta_i_deg + epsilon,
        theta_s_deg=rows.theta_s_deg + epsilon + camera,
    )
    clean = synthetic_measurements(scene, moved, fault_truth(fault)).reflectance
    relative = rows.reflectance_err / rows.reflectance
    own = relative / np.sqrt(np.where(rows.series == "I", 12, 1))
    samples = {n: rng.normal(0.0, POSTERIOR_SCALES["sample"]) for n in dict.fromkeys(rows.sample)}
    series = {n: rng.normal(0.0, errors.calibration_rel) for n in dict.fromkeys(rows.series)}
    random = (
        rng.normal(0.0, own)
        + rng.normal(0.0, POSTERIOR_SCALES["repeatability"], len(rows))
        + np.array([samples[name] for name in rows.sample])
        + np.array([series[name] for name in rows.series])
    )
    scatter = rng.normal(0.0, fault.scatter, len(rows)) if fault.scatter else 0.0
    reflectance = clean * np.exp(fault_shift(fault, rows) + on * (random + scatter))
    return replace(rows, reflectance=reflectance, reflectance_err=relative * reflectance)


def _posterior_checks(scene: Scene, data, seed: int, program):
    """The posterior's checks of ``data`` under ``scene`` from a short NUTS run (:data:`NUTS`),
    its compiled program and its divergent transitions. ``program``: a compiled program of
    ``scene`` (None: compiled here); its model's family object is reused, so the program
    serves this model (:meth:`~brdf_infer.posterior._nuts.NutsProgram.serves` asks for the
    same family object)."""
    from brdf_infer.posterior import (
        build_posterior_model,
        loo_terms,
        posterior_checks,
        psis_loo,
        run_nuts,
    )

    member = program.model.family if program is not None else None
    model = build_posterior_model(scene, data, member)
    draws = run_nuts(model, seed=seed, progress=False, program=program, **NUTS)
    log_lik, cdf = loo_terms(model, draws.sites)
    loo = psis_loo(log_lik, cdf, REFF)
    checks = posterior_checks(model, data, loo.pit, draws.sites)
    divergent = int(np.sum(draws.stats["diverging"]))
    return checks, draws.program, divergent


def replicate_checks(
    scenes: Mapping[str, Scene], rows, fault: Fault, seed: int, replicate: int, programs: dict
) -> dict[str, Any]:
    """Replicate ``replicate`` of ``fault``: its data (:func:`simulate`, the generator seeded
    by (``seed``, ``replicate``)), the least-squares and posterior checks of the fault's scene
    (``programs``: scene name → compiled NUTS program, filled here) and the divergent
    transitions of its NUTS run."""
    from brdf_infer.workflow import lsq_summary

    data = simulate(scenes["lya"], rows, fault, np.random.default_rng([seed, replicate]))
    scene = scenes[fault.scene]
    fit = lsq_summary(scene, data)["model_checks"]
    own, programs[scene.name], divergent = _posterior_checks(
        scene, data, seed + replicate, programs.get(scene.name)
    )
    return {"checks": [*fit, *own], "divergent": divergent}


def model_check_power(
    replicates: int = REPLICATES,
    seed: int = 20240,
    progress: Callable[[str], None] | None = print,
) -> list[dict[str, Any]]:
    """Every fault of :data:`FAULTS` on ``replicates`` data sets each: one dict per fault with
    its ``fault`` and ``size``, ``replicates``, ``failed`` (check name → replicates where it
    failed), ``judged`` (check name → replicates that had it), ``any`` (replicates where some
    check failed: the verdict's ``model_check`` not ok), ``p`` (check name → its p-values),
    ``detectable`` (check name → what it said it could detect, one text a replicate),
    ``divergent`` (replicates whose NUTS run had a divergent transition) and ``seconds``."""
    from brdf_infer.scene import load_scene

    scenes = {name: load_scene(name) for name in ("lya", "lya-fixed")}
    rows = scenes["lya"].load_measurements()
    programs: dict = {}
    result = []
    for fault in FAULTS:
        started = time.perf_counter()
        failed: dict[str, int] = {}
        judged: dict[str, int] = {}
        p_values: dict[str, list] = {}
        detectable: dict[str, list[str]] = {}
        any_failed = divergent = 0
        for replicate in range(replicates):
            outcome = replicate_checks(scenes, rows, fault, seed, replicate, programs)
            for entry in outcome["checks"]:
                name = entry["name"]
                judged[name] = judged.get(name, 0) + 1
                failed[name] = failed.get(name, 0) + (not entry["ok"])
                p_values.setdefault(name, []).append(entry["p"])
                detectable.setdefault(name, []).append(entry["detectable"])
            any_failed += not all(entry["ok"] for entry in outcome["checks"])
            divergent += outcome["divergent"] > 0
        seconds = time.perf_counter() - started
        result.append(
            {
                "fault": fault.name,
                "size": fault.size,
                "replicates": replicates,
                "failed": failed,
                "judged": judged,
                "any": any_failed,
                "p": p_values,
                "detectable": detectable,
                "divergent": divergent,
                "seconds": seconds,
            }
        )
        if progress is not None:
            shares = ", ".join(f"{n} {failed[n]}" for n in _ordered(failed))
            progress(
                f"  model-check power: {fault.name} ({fault.size}): failed of {replicates}: "
                f"{shares}, any {any_failed} ({seconds:.0f} s)"
            )
    return result


def _ordered(names) -> list[str]:
    """Check names in :data:`CHECK_ORDER`, any other after them."""
    names = list(dict.fromkeys(names))
    known = [n for n in CHECK_ORDER if n in names]
    return known + [n for n in names if n not in CHECK_ORDER]


def share_cell(count: int, total: int) -> str:
    """``count`` of ``total`` as a share in % ± its binomial standard error √(p(1−p)/n)."""
    if total <= 0:
        return "—"
    p = count / total
    return f"{100 * p:.0f} ± {100 * math.sqrt(p * (1 - p) / total):.0f} %"


def median_text(texts: list[str]) -> str:
    """The median of texts that differ only in their numbers: each number replaced by the
    median of its place (``.2g``); texts of different wording: the most common one."""
    if not texts:
        return "—"
    templates = {_NUMBER.sub("#", text) for text in texts}
    if len(templates) != 1:
        return statistics.mode(texts)
    columns = zip(*[[float(x) for x in _NUMBER.findall(text)] for text in texts], strict=True)
    medians = iter(f"{statistics.median(column):.2g}" for column in columns)
    return _NUMBER.sub(lambda _: next(medians), texts[0])


def power_section(rows: list[dict[str, Any]]) -> list[str]:
    """The report's section of :func:`model_check_power`'s ``rows``."""
    names = _ordered(name for row in rows for name in row["judged"])
    headers = ["fault", "size", "replicates", *[f"`{n}`" for n in names], "any check"]
    table = []
    for row in rows:
        total = row["replicates"]
        cells = [row["fault"], row["size"], str(total)]
        for name in names:
            judged = row["judged"].get(name, 0)
            cells.append(share_cell(row["failed"].get(name, 0), judged) if judged else "—")
        cells.append(share_cell(row["any"], total))
        table.append(cells)
    replicates = max((row["replicates"] for row in rows), default=0)
    clean = next((row for row in rows if row["size"] == "—"), None)
    stated = []
    if clean is not None:
        stated = [
            f"`{name}`: {median_text(clean['detectable'][name])}"
            for name in names
            if clean["detectable"].get(name)
        ]
    divergent = sum(row["divergent"] for row in rows)
    fits = sum(row["replicates"] for row in rows)
    seconds = sum(row.get("seconds", 0.0) for row in rows)
    noise_free_bound = 100 * 3 / replicates if replicates else math.nan
    return [
        "## Model check: power",
        "",
        "How often each check of a run's `model_check` fails (p < 0.001, or the `at_bound` "
        "rule) on data with a known fault, and on data without one (`none`: its false alarms). "
        "Each data set has the bundled 42 rows' layout (`lya`) and is drawn from the scene's "
        "generative error model at `uv-paper` (`benchmarks._model_check_power.simulate`: "
        "a rotation error per (series, sample, θi) setting and a camera error per row, 1° each, "
        "moving the angles; each row's own sd; the repeatability "
        f"{POSTERIOR_SCALES['repeatability']:g} and sample effects of sd "
        f"{POSTERIOR_SCALES['sample']:g} [ln R], the bundled posterior's medians; one "
        "calibration factor per series of 6.5 %), with the fault planted: α = 3.6 (a2, a3 "
        "rescaled to keep the prior's b2, b3) fitted by `lya-fixed` (α = 4.5, θs0 = −12° "
        "fixed, as the paper); a further lognormal scatter per row of the stated rms; series "
        f"II's rows × {SERIES_FACTOR:g}; ln R + ln {TREND_FACTOR:g}·(θs − mean θs)/range θs. "
        "Each is fitted twice: least squares (`workflow.lsq_summary`, its `fit_*` checks) and "
        f"NUTS ({NUTS['chains']} chains × {NUTS['draws']} draws after {NUTS['warmup']} warmup "
        "iterations), whose PSIS-LOO (relative efficiency 1, no exact refits of high-k rows) "
        "gives the LOO-PIT of the posterior's checks. Replicate i of every fault has the same "
        "noise and NUTS keys. A cell is the share of the replicates where the check failed ± "
        f"its binomial standard error √(p(1−p)/n) (with n = {replicates}: ± 9 % at 50 %, "
        "± 5 % at 10 %; 0 of n bounds the rate below "
        f"{noise_free_bound:.0f} % at 95 %, the rule of three); *any check*: the run's "
        f"`model_check` not ok, its verdict red. NUTS runs with a divergent transition: "
        f"{divergent} of {fits}; {seconds:.0f} s for the section's fits.",
        "",
        markdown_table(headers, table),
        "",
        "What the checks say they could detect (at 80 % power; the median over the unfaulted "
        "replicates of their `detectable` text), to read against the rows above: "
        + "; ".join(stated)
        + ".",
        "",
    ]
