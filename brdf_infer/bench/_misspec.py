"""Benchmark of what SBC cannot see: data simulated under one error model, fitted under another.

SBC (:mod:`brdf_infer.sbc`) simulates from the inference's own likelihood, so it checks the
inference given the model and passes whatever the model gets wrong. Here each case simulates
its replicates under one ``[errors]`` setting of the scene and fits them under another — the
latent angle errors the likelihood linearises, a calibration it leaves out, the other rotation
coupling, another number of images per row — and reports what SBC's rank tests say on those
replicates and how often the posterior intervals cover the truth. Each replicate draws its
truth from the scene's prior (the priors are the same on both sides), as in SBC.

The fits whose settings differ only in options that are data of the compiled likelihood
(:data:`brdf_infer.error_model.DATA_OPTIONS`) share one compiled NUTS program, their data
padded to one shape (:mod:`brdf_infer.posterior._padding`: a zero calibration column adds
nothing); ``angle_method`` only the simulator changes. Every case uses the same seeds, so the
cases share their prior draws and NUTS keys and differ only in how the data were simulated and
fitted.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from brdf_infer.measurements import Measurements
from brdf_infer.posterior import build_posterior_model, chain_keys, programs_by_structure
from brdf_infer.sbc import (
    SbcResult,
    SbcSettings,
    assess_ranks,
    ranked_quantities,
    ranks_of,
    replicate_data,
    simulate,
)
from brdf_infer.scene import Scene
from brdf_infer.sensitivity import variant, variant_scene

REPORTED = ("tis70", "brdf0", "alpha", "theta_s0")  # the quantities of the table
LABELS = {"tis70": "TIS(70°)", "brdf0": "π·BRDF0", "alpha": "α", "theta_s0": "θs0"}
LEVELS = (0.9, 0.95)
SHIFTED = ("tis70", "brdf0")  # the quantities of the table's mean |median − truth| / sd
MAX_REDRAWS = 10  # simulations of spare replicates for those with a non-finite ln R
FULL = SbcSettings(replicates=100)  # SBC's sampler settings, 100 replicates per case
QUICK = SbcSettings(replicates=20, draws=30, thin=1, warmup=150)  # bench --quick


@dataclass(frozen=True)
class MisspecCase:
    """Replicates simulated with the scene's ``[errors]`` keys ``simulated`` changed and
    fitted with its keys ``fitted`` changed (empty: the scene as built)."""

    name: str
    simulated: dict[str, Any] = field(default_factory=dict)
    fitted: dict[str, Any] = field(default_factory=dict)


WIDER_ANGLES = {"rotation_deg": 2.0, "camera_deg": 2.0}  # twice the article's 1°
CASES: tuple[MisspecCase, ...] = (
    MisspecCase("well specified"),
    MisspecCase("latent angles", simulated={"angle_method": "latent"}),
    MisspecCase(
        "latent angles, 2°",
        simulated={"angle_method": "latent", **WIDER_ANGLES},
        fitted=WIDER_ANGLES,
    ),
    MisspecCase("calibration left out", fitted={"calibration": "none"}),
    MisspecCase(
        "3 × calibration left out",
        simulated={"calibration_rel": 0.195},  # 3 × the bundled scene's 6.5 %
        fitted={"calibration": "none"},
    ),
    MisspecCase(
        "per-sample calibration left out",
        simulated={"calibration": "per_sample"},
        fitted={"calibration": "none"},
    ),
    MisspecCase("camera fixed, fitted following", simulated={"rotation_coupling": "camera_fixed"}),
    MisspecCase("camera following, fitted fixed", fitted={"rotation_coupling": "camera_fixed"}),
    MisspecCase("series I of 1 image, fitted 12", simulated={"images_per_row": 1}),
)


@dataclass(frozen=True)
class MisspecResult:
    """One case: SBC's rank tests on its replicates (``ranks``: a :class:`SbcResult`), the
    mean over replicates of |posterior median − truth| / posterior sd per quantity
    (``shift``), the replicates simulated again for a non-finite ln R (``redrawn``,
    :func:`simulate_case`) and the case's wall time [s] (simulating and sampling)."""

    case: MisspecCase
    ranks: SbcResult
    shift: dict[str, float]
    redrawn: int
    seconds: float

    @property
    def min_p(self) -> float:
        """The smallest χ² or KS p-value of the rank tests."""
        r = self.ranks
        return min(min(r.chi2_p[q], r.ks_p[q]) for q in r.quantities)

    @property
    def cells(self) -> list[str]:
        r = self.ranks
        failed = sorted({failure.split(":")[0] for failure in r.failures})
        verdict = "pass" if r.passed else f"fail ({', '.join(failed)})"
        coverage = [  # a quantity the scene fixes has no interval
            " / ".join(f"{r.coverage[level][q]:.0%}" for level in LEVELS)
            if q in r.coverage[0.9]
            else "fixed"
            for q in REPORTED
        ]
        return [
            self.case.name,
            describe(self.case.simulated),
            describe(self.case.fitted),
            f"{verdict}, min p {self.min_p:.2g}",
            *coverage,
            " / ".join(f"{self.shift[q]:.2f}" if q in self.shift else "–" for q in SHIFTED),
            str(int(np.sum(r.divergences > 0))),
            f"{self.seconds:.0f}",
        ]


HEADERS = [
    "case",
    "simulated under",
    "fitted under",
    "SBC rank tests",
    *(f"{LABELS[q]} 90 / 95 %" for q in REPORTED),
    "mean abs Δ/sd, TIS(70°) / π·BRDF0",
    "replicates with divergences",
    "wall [s]",
]


def describe(changes: dict[str, Any]) -> str:
    """A side of a case in the table: ``as built`` or the changed ``[errors]`` keys."""
    return f"`{variant(changes).name}`" if changes else "as built"


def case_scene(scene: Scene, changes: dict[str, Any]) -> Scene:
    """``scene`` with these ``[errors]`` keys changed (validated as its own table would be)."""
    return variant_scene(scene, variant(changes), field_name="misspecification case")


def simulate_case(
    scene: Scene, measurements: Measurements, case: MisspecCase, replicates: int, seed: int
) -> tuple[dict[str, np.ndarray], int]:
    """Prior draws of every site and a simulated ``obs`` (ln R of every row) per replicate
    (leading axis) under the scene with the case's ``simulated`` keys changed, and how many
    replicates were drawn again (below). :func:`brdf_infer.sbc.simulate`: the model in simulate
    mode; with ``angle_method = "latent"`` the angle errors are drawn and ln R evaluated at the
    perturbed angles.

    A latent θs pushed to 90° or beyond has no ln cos θs (the row would look at the sample
    edge-on): such a replicate is drawn again, with seeds ``seed + 1, seed + 2, …`` until every
    replicate is finite. That truncates the angle errors to the physical range; the
    parameters do not enter the condition, so their prior is unchanged.

    Raises:
        RuntimeError: no finite replacement after :data:`MAX_REDRAWS` attempts.
    """
    model = build_posterior_model(case_scene(scene, case.simulated), measurements)
    simulated = {
        name: np.array(values) for name, values in simulate(model, replicates, seed).items()
    }
    redrawn = set()
    for attempt in range(1, MAX_REDRAWS + 1):
        bad = np.flatnonzero(~np.all(np.isfinite(simulated["obs"]), axis=1))
        if not len(bad):
            return simulated, len(redrawn)
        redrawn.update(bad.tolist())
        spare = simulate(model, replicates, seed + attempt)
        finite = np.flatnonzero(np.all(np.isfinite(spare["obs"]), axis=1))[: len(bad)]
        for name, values in simulated.items():
            values[bad[: len(finite)]] = spare[name][finite]
    raise RuntimeError(f"{case.name}: simulated ln R not finite after {MAX_REDRAWS} redraws")


def run_cases(
    scene: Scene,
    measurements: Measurements,
    cases: tuple[MisspecCase, ...] = CASES,
    settings: SbcSettings = FULL,
    progress=None,
) -> list[MisspecResult]:
    """Every case with SBC's sampler settings (``settings``; its ``sigma_scale`` and
    ``planted_fault`` must be the defaults); the fits of one model structure share one compiled
    NUTS program.

    Raises:
        ValueError: a planted fault or σ scale in ``settings``.
        BadInputError: a case whose changes are not a valid ``[errors]`` table of the scene.
    """
    if settings.planted_fault is not None or settings.sigma_scale != 1.0:
        raise ValueError("the misspecification study plants no fault in the inference")
    fitted = [case_scene(scene, case.fitted) for case in cases]
    for case in cases:  # every case checked before any sampling
        case_scene(scene, case.simulated)
    models = [build_posterior_model(each, measurements) for each in fitted]
    keys = chain_keys(settings.seed + 1, settings.replicates, 1)
    results: list[MisspecResult | None] = [None] * len(cases)
    grouped = programs_by_structure(
        models,
        warmup=settings.warmup,
        target_accept=settings.target_accept,
        warmup_tree_depth=settings.warmup_tree_depth,
    )
    for program, members in grouped:
        for index, data in members:
            case = cases[index]
            if progress is not None:
                progress(f"  misspecification, {case.name}, {settings.replicates} replicates")
            started = time.perf_counter()
            simulated, redrawn = simulate_case(
                scene, measurements, case, settings.replicates, settings.seed
            )
            output = program.run_many(
                replicate_data(data, simulated["obs"]), keys, settings.draws * settings.thin
            )
            truth, posterior = ranked_quantities(
                models[index], simulated, output.sites, settings.thin
            )
            ranks = assess_ranks(settings, ranks_of(truth, posterior))
            divergences = np.sum(output.stats["diverging"], axis=(1, 2))
            results[index] = MisspecResult(
                case,
                dataclasses.replace(ranks, divergences=divergences),
                standardised_errors(truth, posterior, ranks.quantities),
                redrawn,
                time.perf_counter() - started,
            )
    return [result for result in results if result is not None]


def standardised_errors(
    truth: dict[str, np.ndarray], posterior: dict[str, np.ndarray], names: tuple[str, ...]
) -> dict[str, float]:
    """Mean over replicates of |posterior median − truth| / posterior sd, per quantity (for a
    calibrated normal posterior its expectation is √(2/π) ≈ 0.80)."""
    return {
        name: float(
            np.mean(
                np.abs(np.median(posterior[name], axis=1) - truth[name])
                / np.std(posterior[name], axis=1)
            )
        )
        for name in names
    }


def misspec_rows(scene: Scene, quick: bool, progress=print) -> list[MisspecResult]:
    """:data:`CASES` on ``scene`` (the bundled one): 100 replicates each with SBC's default
    sampler settings, or 20 at the quick benchmark's smaller settings."""
    settings = QUICK if quick else FULL
    return run_cases(scene, scene.load_measurements(), CASES, settings, progress)


def section_text(rows: list[MisspecResult]) -> tuple[str, str]:
    """(the paragraph before the table, the one after it) of the benchmark's section."""
    first = rows[0].ranks
    settings = first.settings
    low, high = first.coverage_range[0.9]
    before = (
        "SBC (above) simulates from the likelihood itself, so it checks the inference given "
        "the model and cannot see a wrong error model. Each case here simulates "
        f"{settings.replicates} replicates under one `[errors]` setting of the bundled scene "
        "and fits them under another (`brdf_infer/bench/_misspec.py`): each replicate's truth "
        "is drawn from the scene's prior and its data at the 42 rows; NUTS as in SBC "
        f"({settings.warmup} warmup, {settings.draws * settings.thin} draws thinned to "
        f"{settings.draws}); every case has the same prior draws and NUTS keys. *SBC rank "
        "tests*: SBC's own tests (χ², KS and 90 % coverage of the six parameters, TIS(70°) and "
        "the learned noise scales, family-wise 1 %; min p the smallest χ² or KS p-value) on "
        "these replicates — what SBC would say if its simulator carried the mismatch; the "
        "first row is SBC itself. Coverage: the "
        "fraction of replicates whose central 90 / 95 % posterior interval holds the truth; for "
        f"a calibrated posterior the 90 % figure lies in {low:.0%}–{high:.0%} (the verdict's "
        f"range at {settings.replicates} replicates). Mean abs Δ/sd: |posterior median − truth|"
        " / posterior sd, averaged over replicates; ≈ 0.80 when calibrated. `angle_method="
        "latent` draws the angle errors as angles and evaluates ln R at the perturbed angles, "
        "where the likelihood linearises ln R in them; the 2° row simulates and fits angle "
        "errors of 2°, twice the article's. Wall time: simulating and sampling (the first row "
        "of each compiled program also compiles it)."
    )
    redrawn = [f"{row.case.name}: {row.redrawn}" for row in rows if row.redrawn]
    after = (
        "Replicates drawn again because a latent θs reached 90° (no ln cos θs there; the "
        "angle errors are truncated to the physical range): "
        + (", ".join(redrawn) if redrawn else "none")
        + f". Total {sum(row.seconds for row in rows):.0f} s."
    )
    return before, after
