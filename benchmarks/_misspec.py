"""Benchmark of what SBC cannot see: data simulated under one error model, fitted under another.

SBC (:mod:`brdf_infer.studies.sbc`) simulates from the inference's own likelihood, so it checks the
inference given the model and passes whatever the model gets wrong. Here each case simulates
its replicates under one ``[errors]`` setting of the scene and fits them under another — the
latent angle errors the likelihood linearises, a calibration it leaves out, the other rotation
coupling, another number of images per row — and reports what SBC's rank tests say on those
replicates and how often the posterior intervals cover the truth, each coverage with its
binomial Monte Carlo standard error.

Two blocks of truths. *Prior*: each replicate draws its truth from the scene's prior
(:func:`brdf_infer.studies.sbc.simulate`), as SBC does; but the prior's noise scales (sample sd,
repeatability) are several times the data's (the section states both blocks' medians), and
beside such noise a left-out calibration of a few per cent barely shows. *Posterior*: each
replicate's truth — the parameters and the learned noise scales — is a draw of the scene's
posterior on its own data (a NUTS run made here, :func:`posterior_truths`), where the coating
and the instrument plausibly are; the full generative model (every other site drawn: the
latent effects, or with ``angle_method = "latent"`` the angle errors) is simulated at it,
:func:`simulate_at`. A posterior draw is no prior draw, so the ranks of the posterior block
need not be uniform even when the model is right: its well-specified row is the reference
the other rows are read against.

The fits whose settings differ only in options that are data of the compiled likelihood
(:data:`brdf_infer.model.error_model.DATA_OPTIONS`) share one compiled NUTS program, their data
padded to one shape (:mod:`brdf_infer.posterior._padding`: a zero calibration column adds
nothing); ``angle_method`` only the simulator changes. Every case of a block uses the same
seeds and truths, so the cases share their truths and NUTS keys and differ only in how the data
were simulated and fitted.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Any

import jax
import numpy as np
from numpyro import handlers
from numpyro.infer import Predictive

from brdf_infer.posterior import (
    NOISE_SITES,
    PosteriorModel,
    build_posterior_model,
    chain_keys,
    programs_by_structure,
    run_nuts,
)
from brdf_infer.scene import Scene
from brdf_infer.studies.sbc import (
    SbcResult,
    SbcSettings,
    assess_ranks,
    ranked_quantities,
    ranks_of,
    replicate_data,
    simulate,
)
from brdf_infer.studies.sensitivity import variant, variant_scene
from brdf_infer.tables.measurements import Measurements

REPORTED = ("tis70", "brdf0", "alpha", "theta_s0")  # the quantities of the table
LABELS = {"tis70": "TIS(70°)", "brdf0": "π·BRDF0", "alpha": "α", "theta_s0": "θs0"}
LEVELS = (0.9, 0.95)
SHIFTED = ("tis70", "brdf0")  # the quantities of the table's mean |median − truth| / sd
MAX_REDRAWS = 10  # simulations of spare replicates for those with a non-finite ln R
FULL = SbcSettings(replicates=100)  # SBC's sampler settings, 100 replicates per case
QUICK = SbcSettings(replicates=20, draws=30, thin=1, warmup=150)  # bench --quick
# the NUTS run whose draws are the posterior block's truths: `brdf-infer run`'s defaults, and
# a smaller one for bench --quick
POSTERIOR_RUN = {"chains": 4, "warmup": 1000, "draws": 1000}
QUICK_POSTERIOR_RUN = {"chains": 2, "warmup": 300, "draws": 200}
BLOCKS = ("prior", "posterior")  # where a block's truths are drawn from


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

    def coverage_error(self, level: float, name: str) -> float:
        """The binomial Monte Carlo standard error √(c (1 − c) / N) of a coverage c measured
        on N replicates."""
        c = self.ranks.coverage[level][name]
        return float(np.sqrt(c * (1 - c) / self.ranks.settings.replicates))

    @property
    def cells(self) -> list[str]:
        r = self.ranks
        failed = sorted({failure.split(":")[0] for failure in r.failures})
        verdict = "pass" if r.passed else f"fail ({', '.join(failed)})"
        coverage = [  # a quantity the scene fixes has no interval
            " / ".join(
                f"{r.coverage[level][q]:.0%} ± {self.coverage_error(level, q) * 100:.0f}"
                for level in LEVELS
            )
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
    *(f"{LABELS[q]} 90 / 95 % ± MC se" for q in REPORTED),
    "mean abs Δ/sd, TIS(70°) / π·BRDF0",
    "replicates with divergences",
    "wall [s]",
]


@dataclass(frozen=True)
class PosteriorTruths:
    """The posterior block's truths: ``sites``, one value per truth (leading axis) of every
    parameter and learned noise scale the scene's simulate mode draws, each truth a distinct
    draw of a NUTS run of the scene on its own data (``run``: its chains, warmup and draws per
    chain; ``divergences``: its divergent transitions; ``seconds``: its wall time, compiling
    included)."""

    sites: dict[str, np.ndarray]
    run: dict[str, int]
    divergences: int
    seconds: float


@dataclass(frozen=True)
class MisspecStudy:
    """The cases with truths from the scene's prior (``prior``; ``prior_noise``: the median
    of each learned noise scale among its truths) and from its posterior (``posterior``, at
    ``truths``)."""

    prior: list[MisspecResult]
    posterior: list[MisspecResult]
    truths: PosteriorTruths
    prior_noise: dict[str, float]


def describe(changes: dict[str, Any]) -> str:
    """A side of a case in the table: ``as built`` or the changed ``[errors]`` keys."""
    return f"`{variant(changes).name}`" if changes else "as built"


def case_scene(scene: Scene, changes: dict[str, Any]) -> Scene:
    """``scene`` with these ``[errors]`` keys changed (validated as its own table would be)."""
    return variant_scene(scene, variant(changes), field_name="misspecification case")


LATENT_ANGLE_SITES = ("rotation_error_std", "camera_error_std", "rotation_alone_error_std")


def truth_sites(model: PosteriorModel) -> tuple[str, ...]:
    """The sites a truth sets in ``model``'s simulate mode: every drawn site but ``obs`` and
    the latent angle errors (for the bundled scene the six parameters in their internal
    coordinates and the two learned noise scales; a factor is no drawn site)."""
    trace = handlers.trace(handlers.seed(model, 0)).get_trace(mode="simulate")
    return tuple(
        name
        for name, site in trace.items()
        if site["type"] == "sample"
        and not site["is_observed"]
        and name != "obs"
        and name not in LATENT_ANGLE_SITES
    )


def posterior_truths(
    scene: Scene, measurements: Measurements, count: int, seed: int, run: dict[str, int]
) -> PosteriorTruths:
    """``count`` distinct draws, chosen at random (``seed``), of a NUTS run (``run``: chains,
    warmup, draws per chain; :func:`brdf_infer.posterior.run_nuts`) of ``scene``'s posterior
    on ``measurements``, at every site of :func:`truth_sites`.

    Raises:
        ValueError: fewer pooled draws than ``count``.
    """
    started = time.perf_counter()
    model = build_posterior_model(scene, measurements)
    draws = run_nuts(model, seed=seed, progress=False, **run)
    pooled = run["chains"] * run["draws"]
    if pooled < count:
        raise ValueError(f"{count} truths asked of a run of {pooled} draws")
    chosen = np.random.default_rng(seed).choice(pooled, size=count, replace=False)
    sites = {
        name: np.asarray(draws.sites[name]).reshape(pooled, *np.shape(draws.sites[name])[2:])[
            chosen
        ]
        for name in truth_sites(model)
    }
    return PosteriorTruths(
        sites,
        dict(run),
        int(np.sum(draws.stats["diverging"])),
        time.perf_counter() - started,
    )


def simulate_at(
    model: PosteriorModel, truths: dict[str, np.ndarray], seed: int
) -> dict[str, np.ndarray]:
    """Every site of ``model``'s simulate mode, one replicate per truth (leading axis): the
    sites ``truths`` names set to them, every other site — the latent angle errors, ``obs`` —
    drawn from the full generative model given them, and the deterministic sites (the physical
    parameters) computed from them. A site of ``truths`` that ``model`` does not have is
    returned as it is."""
    truths = {name: np.asarray(values) for name, values in truths.items()}

    @jax.jit
    def draw(key, values):
        return Predictive(model, posterior_samples=values, parallel=True)(key, mode="simulate")

    drawn = jax.device_get(draw(jax.random.PRNGKey(seed), truths))
    return {**truths, **drawn}


def simulate_case(
    scene: Scene,
    measurements: Measurements,
    case: MisspecCase,
    replicates: int,
    seed: int,
    truths: dict[str, np.ndarray] | None = None,
) -> tuple[dict[str, np.ndarray], int]:
    """The truth of every site and a simulated ``obs`` (ln R of every row) per replicate
    (leading axis) under the scene with the case's ``simulated`` keys changed, and how many
    replicates were drawn again (below). Without ``truths`` each replicate's truth is a prior
    draw (:func:`brdf_infer.studies.sbc.simulate`: the model in simulate mode); with them (one per
    replicate) the model is simulated at them (:func:`simulate_at`). With ``angle_method =
    "latent"`` the angle errors are drawn and ln R evaluated at the perturbed angles.

    A latent θs pushed to 90° or beyond has no ln cos θs (the row would look at the sample
    edge-on): such a replicate is replaced by the same replicate of a simulation with seed
    ``seed + 1``, ``seed + 2``, … until every replicate is finite — with ``truths`` at the same
    truth, else a new prior draw. That truncates the angle errors to the physical range; the
    parameters do not enter the condition, so their distribution is unchanged.

    Raises:
        RuntimeError: no finite replacement after :data:`MAX_REDRAWS` attempts.
    """
    model = build_posterior_model(case_scene(scene, case.simulated), measurements)

    def draw(each_seed: int) -> dict[str, np.ndarray]:
        if truths is None:
            return simulate(model, replicates, each_seed)
        return simulate_at(model, truths, each_seed)

    simulated = {name: np.array(values) for name, values in draw(seed).items()}
    redrawn = set()
    for attempt in range(1, MAX_REDRAWS + 1):
        bad = np.flatnonzero(~np.all(np.isfinite(simulated["obs"]), axis=1))
        if not len(bad):
            return simulated, len(redrawn)
        redrawn.update(bad.tolist())
        spare = draw(seed + attempt)
        replaced = bad[np.all(np.isfinite(spare["obs"][bad]), axis=1)]
        for name, values in simulated.items():
            values[replaced] = spare[name][replaced]
    raise RuntimeError(f"{case.name}: simulated ln R not finite after {MAX_REDRAWS} redraws")


def run_cases(
    scene: Scene,
    measurements: Measurements,
    cases: tuple[MisspecCase, ...] = CASES,
    settings: SbcSettings = FULL,
    progress=None,
    truths: dict[str, np.ndarray] | None = None,
) -> list[MisspecResult]:
    """Every case with SBC's sampler settings (``settings``; its ``sigma_scale`` and
    ``planted_fault`` must be the defaults) and its replicates' truths drawn from the prior,
    or set to ``truths`` (one per replicate: :func:`simulate_case`); the fits of one model
    structure share one compiled NUTS program.

    Raises:
        ValueError: a planted fault or σ scale in ``settings``, or ``truths`` not one per
            replicate.
        BadInputError: a case whose changes are not a valid ``[errors]`` table of the scene.
    """
    if settings.planted_fault is not None or settings.sigma_scale != 1.0:
        raise ValueError("the misspecification study plants no fault in the inference")
    if truths is not None and any(
        np.shape(values)[0] != settings.replicates for values in truths.values()
    ):
        raise ValueError(f"the study needs one truth per replicate ({settings.replicates})")
    block = "prior" if truths is None else "posterior"
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
                progress(
                    f"  misspecification, {block} truths, {case.name}, "
                    f"{settings.replicates} replicates"
                )
            started = time.perf_counter()
            simulated, redrawn = simulate_case(
                scene, measurements, case, settings.replicates, settings.seed, truths
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


def misspec_rows(scene: Scene, quick: bool, progress=print) -> MisspecStudy:
    """:data:`CASES` on ``scene`` (the bundled one) in both blocks: 100 replicates each with
    SBC's default sampler settings and truths from a NUTS run of :data:`POSTERIOR_RUN`, or 20
    at the quick benchmark's smaller settings (:data:`QUICK_POSTERIOR_RUN`)."""
    settings = QUICK if quick else FULL
    measurements = scene.load_measurements()
    prior = run_cases(scene, measurements, CASES, settings, progress)
    if progress is not None:
        progress("  misspecification, the posterior run of the truths")
    run = QUICK_POSTERIOR_RUN if quick else POSTERIOR_RUN
    truths = posterior_truths(scene, measurements, settings.replicates, settings.seed, run)
    posterior = run_cases(scene, measurements, CASES, settings, progress, truths.sites)
    prior_draws = simulate(
        build_posterior_model(scene, measurements), settings.replicates, settings.seed
    )
    return MisspecStudy(prior, posterior, truths, noise_medians(prior_draws))


def noise_medians(sites: dict[str, np.ndarray]) -> dict[str, float]:
    """The median of each learned noise scale among truths (leading axis)."""
    return {name: float(np.median(sites[name])) for name in NOISE_SITES if name in sites}


def section_text(study: MisspecStudy) -> tuple[str, str, str, str]:
    """(the paragraph before the tables, the one before the prior block's table, the one
    before the posterior block's, the one after them) of the benchmark's section."""
    first = study.prior[0].ranks
    settings = first.settings
    low, high = first.coverage_range[0.9]
    truths = study.truths
    run = truths.run

    def medians(values: dict[str, float]) -> str:
        return " and ".join(f"{values[name]:.3f}" for name in NOISE_SITES if name in values)

    before = (
        "SBC (above) simulates from the likelihood itself, so it checks the inference given "
        "the model and cannot see a wrong error model. Each case here simulates "
        f"{settings.replicates} replicates under one `[errors]` setting of the bundled scene "
        "and fits them under another (`benchmarks/_misspec.py`), its data at the 42 "
        f"rows; NUTS as in SBC ({settings.warmup} warmup, {settings.draws * settings.thin} "
        f"draws thinned to {settings.draws}); every case of a block has the same truths and "
        "NUTS keys. Two blocks, by where the truths are drawn: from the scene's prior, as in "
        "SBC, and from its posterior on the bundled data, where the coating and the instrument "
        "plausibly are. *SBC rank tests*: SBC's own tests (χ², KS and 90 % coverage of the six "
        "parameters, TIS(70°) and the learned noise scales, family-wise 1 %; min p the "
        "smallest χ² or KS p-value) on these replicates — what SBC would say if its simulator "
        "carried the mismatch. Coverage: the fraction of replicates whose central 90 / 95 % "
        "posterior interval holds the truth, ± its binomial Monte Carlo standard error "
        "√(c (1 − c) / N) in points; for a calibrated posterior at prior truths the 90 % "
        f"figure lies in {low:.0%}–{high:.0%} (the verdict's range at {settings.replicates} "
        "replicates). Mean abs Δ/sd: |posterior median − truth| / posterior sd, averaged over "
        "replicates; ≈ 0.80 when calibrated. `angle_method=latent` draws the angle errors as "
        "angles and evaluates ln R at the perturbed angles, where the likelihood linearises ln "
        "R in them; the 2° row simulates and fits angle errors of 2°, twice the article's. "
        "Wall time: simulating and sampling (the first row of each compiled program also "
        "compiles it)."
    )
    prior_text = (
        "**Truths from the prior** (`brdf_infer.studies.sbc.simulate`): every parameter and noise "
        "scale of a replicate drawn from the scene's prior; the first row is SBC itself. The "
        "prior's noise scales are wide: the truths' median sample sd and repeatability are "
        f"{medians(study.prior_noise)}, against the bundled scene's 6.5 % calibration per "
        "series."
    )
    posterior_text = (
        "**Truths from the posterior**: a NUTS run of the bundled scene on its own data "
        f"({run['chains']} chains of {run['warmup']} warmup and {run['draws']} draws, "
        f"{truths.divergences} divergent transitions, {truths.seconds:.0f} s), "
        f"{settings.replicates} of its {run['chains'] * run['draws']} draws chosen at random "
        "without replacement; each sets a replicate's six parameters and its sample sd and "
        "repeatability (truths' medians "
        f"{medians(noise_medians(truths.sites))}), and the full generative model is simulated "
        "at it (every other site drawn: the sample, calibration and angle effects, or the "
        "latent angle errors). A posterior draw is no prior draw, so the ranks need not be "
        "uniform and the coverage need not be nominal even when the model is right: the "
        "well-specified row is the reference the others are read against."
    )
    redrawn = [
        f"{block}, {row.case.name}: {row.redrawn}"
        for block, rows in zip(BLOCKS, (study.prior, study.posterior), strict=True)
        for row in rows
        if row.redrawn
    ]
    total = sum(row.seconds for row in (*study.prior, *study.posterior)) + truths.seconds
    after = (
        "Replicates drawn again because a latent θs reached 90° (no ln cos θs there; the "
        "angle errors are truncated to the physical range): "
        + (", ".join(redrawn) if redrawn else "none")
        + f". Total {total:.0f} s (the posterior run included)."
    )
    return before, prior_text, posterior_text, after
