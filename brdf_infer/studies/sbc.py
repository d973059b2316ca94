"""Simulation-based calibration (Talts et al. 2018, arXiv:1804.06788) of a scene's posterior.

For each replicate: draw the parameters and every latent from the scene's physical prior
(its ``[priors]`` without coatings that scatter more than they receive), simulate a
data set at the scene's own geometry through the scene's own generative model (the NumPyro
model in ``simulate`` mode), sample its posterior with NUTS, and rank the true value among L
thinned posterior draws. If the posterior is calibrated, the ranks of every quantity are
uniform on {0, …, L}. All replicates run side by side in one compiled, vmapped NUTS program.

Checks, per quantity (the family's physical parameters, for ``strumik2024`` the six of
Eq. 7 in paper units; TIS(70°), and where the rows carry sample effects TIS(70°) of the
sample(s) measured and of a new part (:func:`target_quantities`); and the learned noise
scales of the error model, ``sample_sd`` and ``repeatability``, where the scene learns them):
χ² of the rank histogram (up to 20 bins of whole ranks, at least 10 replicates expected in
each) against uniform counts, Kolmogorov–Smirnov of the randomised ranks (rank + U)/(L + 1)
against U(0, 1), and the coverage of the central 50/90/95 % posterior intervals against the
binomial 99 % range. The verdict
controls the family-wise error over every test it runs (Bonferroni over the three tests — χ²,
KS, 90 % coverage — of each of the m quantities: each fails below 0.01/(3m)), so a calibrated
posterior passes at least 99 % of the time whatever the number of quantities (tested on uniform
null ranks); the raw p-values are reported too. A quantity the scene fixes (e.g. α and θs0
of ``lya-fixed``) equals its truth in every draw: it has no rank to test and is left out.

What it checks. The simulator is the model itself: the same NumPyro model, in ``simulate``
mode, with the latent effects marginalised and the angle slopes linearised at the truth, just
as the likelihood has them. SBC therefore checks the inference *given the model* — the
sampler, the whitened reparametrisation and its Jacobian, and that the inference's priors are
the simulator's — and cannot see a wrong model (a wrong calibration size, rotation coupling
or images per row, or the linearisation of the angle slopes): data and inference would share
the error. The benchmark's misspecification study (:mod:`benchmarks._misspec`) measures
what such errors cost the intervals. Planted faults in the inference only show that the check
has power against what it checks: ``planted_fault``
(:data:`brdf_infer.scene.settings.PLANTED_FAULTS`: the whitening's log-Jacobian dropped, or every
free prior moved by one prior sd) and ``sigma_scale`` (the likelihood's σ scaled; the learned
noise scales absorb most of it, so it fails through them).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from scipy import stats

from brdf_infer.errors import BadInputError
from brdf_infer.model import ModelFamily, check_family_name, family
from brdf_infer.model.params import PARAM_NAMES
from brdf_infer.model.priors import Prior
from brdf_infer.posterior import (
    LINEAR,
    NOISE_SITES,
    ModelData,
    NutsProgram,
    PosteriorModel,
    build_model,
    chain_keys,
    latent_effect_draws,
    prior_draws,
    target_log_factor,
)
from brdf_infer.runs.folder import SBC_FILE as SBC_FILE  # the old name, kept
from brdf_infer.scene import Scene
from brdf_infer.scene.settings import SbcSettings, check_planted_fault_name
from brdf_infer.tables.measurements import Measurements

QUANTITIES: tuple[str, ...] = (*PARAM_NAMES, "tis70")  # ranked for strumik2024
NOISE_QUANTITIES: tuple[str, ...] = NOISE_SITES
COVERAGE_LEVELS: tuple[float, ...] = (0.5, 0.9, 0.95)
FAMILY_ALPHA = 0.01  # family-wise level of the verdict
TESTS_PER_QUANTITY = 3  # χ², KS and the 90 % coverage
HISTOGRAM_BINS = 20
MIN_EXPECTED_PER_BIN = 10  # replicates per bin of the χ² test, at least


@dataclass(frozen=True)
class SbcResult:
    """Ranks, tests and coverage of one SBC run (``as_json`` gives the JSON contract)."""

    settings: SbcSettings
    ranks: dict[str, np.ndarray]
    chi2_p: dict[str, float]
    ks_p: dict[str, float]
    coverage: dict[float, dict[str, float]]
    coverage_range: dict[float, tuple[float, float]]
    divergences: np.ndarray
    failures: list[str]
    seconds: float
    compile_seconds: float

    @property
    def passed(self) -> bool:
        return not self.failures

    @property
    def quantities(self) -> tuple[str, ...]:
        return tuple(self.ranks)

    def as_json(self) -> dict[str, Any]:
        settings = self.settings
        return {
            "replicates": settings.replicates,
            "draws": settings.draws,
            "quantities": {
                name: {
                    "ranks": self.ranks[name].tolist(),
                    "chi2_p": self.chi2_p[name],
                    "ks_p": self.ks_p[name],
                }
                for name in self.quantities
            },
            "coverage": {str(level): dict(values) for level, values in self.coverage.items()},
            "coverage_range_99": {
                str(level): list(bounds) for level, bounds in self.coverage_range.items()
            },
            "passed": self.passed,
            "failures": self.failures,
            "family_alpha": FAMILY_ALPHA,
            "settings": dataclasses.asdict(settings),
            "divergent_replicates": int(np.sum(self.divergences > 0)),
            "seconds": self.seconds,
            "compile_seconds": self.compile_seconds,
            "seconds_per_replicate": (self.seconds - self.compile_seconds) / settings.replicates,
        }


def _tis70(sites: dict, member: ModelFamily) -> np.ndarray:
    """TIS(70°) of every draw (any leading shape), with the family's fold (the scene's, as the
    run reports it); only its order matters to the ranks."""
    flat = {name: jnp.asarray(sites[name]).reshape(-1) for name in member.parameters}
    shape = np.shape(sites[member.parameters[0]])
    if member.log_tis_draws is not None:  # Eq. (9), batched over the draws in one call
        values = member.log_tis_draws(jnp.array([70.0]), flat)[..., 0]
    else:  # a 2-D quadrature per draw, in batches
        values = jax.jit(
            lambda p: jax.lax.map(lambda one: member.tis(70.0, one), p, batch_size=64)
        )(flat)
    return np.asarray(values).reshape(shape)


def _ranked_values(sites: dict, member: ModelFamily) -> dict[str, np.ndarray]:
    """The ranked quantities of draws (any leading shape): the family's physical parameters,
    TIS(70°) and the learned noise scales."""
    values = {name: np.asarray(sites[name]) for name in member.parameters}
    values["tis70"] = _tis70(sites, member)
    values.update({name: np.asarray(sites[name]) for name in NOISE_QUANTITIES if name in sites})
    return values


def simulate(model: PosteriorModel, replicates: int, seed: int) -> dict[str, np.ndarray]:
    """Draws of every site of the physical prior (no coating with TIS > 1) and a simulated
    ``obs`` per replicate (leading axis): :func:`brdf_infer.posterior.prior_draws`."""
    return prior_draws(model, replicates, seed)


def replicate_data(data: ModelData, log_reflectance: np.ndarray) -> ModelData:
    """``data`` once per simulated data set, each with its own ln R: ``log_reflectance`` is
    (data sets, rows), the result's every leaf gains that leading axis."""
    count = int(np.shape(log_reflectance)[0])
    datasets = jax.tree_util.tree_map(
        lambda leaf: jnp.broadcast_to(leaf, (count, *jnp.shape(leaf))), data
    )
    return datasets._replace(
        rows=datasets.rows._replace(log_reflectance=jnp.asarray(log_reflectance))
    )


def ranked_quantities(
    model: PosteriorModel,
    simulated: dict,
    sites: dict[str, np.ndarray],
    thin: int,
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """(truth, posterior) of the quantities SBC ranks, for the family ``model`` samples.

    Args:
        model: the inference's model (its scene's fold and constants, its family).
        simulated: the true sites, one value per replicate (leading axis).
        sites: NUTS draws of one chain per replicate, (replicates, 1, iterations, ...).
        thin: keep every ``thin``-th draw.

    Returns:
        The truths (replicates,) and the thinned draws (replicates, draws) of each quantity.
    """
    thinned = {k: v[:, 0, thin - 1 :: thin] for k, v in sites.items()}
    return _ranked_values(simulated, model.family), _ranked_values(thinned, model.family)


def target_quantities(
    models: tuple[PosteriorModel, PosteriorModel],
    simulated: dict,
    sites: dict[str, np.ndarray],
    datasets: ModelData,
    settings: SbcSettings,
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """(truth, posterior) of TIS(70°) of the sample(s) measured and of a new part
    (:mod:`brdf_infer.posterior._targets`), ``tis70_measured`` and ``tis70_new_part``, and, for
    a pooled scene (``[campaigns]``), of each calibration factor κ_g, ``calibration_1``, … in
    the order of W's calibration columns
    (:func:`brdf_infer.model.error_model.calibration_group_names`; true κ drawn from
    p(κ | θ, y) as the effects are).

    The simulator marginalises the sample effects, so each replicate's true effects are drawn
    from their conditional given its true parameters and its data, p(u | θ, y): with θ from
    the prior and y from p(y | θ), that makes (θ, u, y) a draw of the joint. A new part's true
    effect is τ z. The posterior's are the run's: each thinned draw's u from p(u | θ_s, y)
    under the inference's model, a new part's τ_s z_s.

    Args:
        models: the simulator's model and the inference's (a planted fault's).
        simulated: the true sites, one value per replicate (leading axis).
        sites: NUTS draws of one chain per replicate, (replicates, 1, iterations, ...).
        datasets: each replicate's data (leading axis).
        settings: the SBC settings (thinning, seed).
    """
    model, inference = models
    thinned = {k: v[:, 0, settings.thin - 1 :: settings.thin] for k, v in sites.items()}
    replicates = len(simulated["obs"])
    names = model.sample_names
    truth_tis = _tis70(simulated, model.family)
    draws_tis = _tis70(thinned, model.family)
    rng = np.random.default_rng(settings.seed + 5)
    truth = {"tis70_measured": np.empty(replicates), "tis70_new_part": np.empty(replicates)}
    posterior = {name: np.empty_like(draws_tis) for name in truth}
    # a pooled scene's calibration factors (others' would add quantities to the Bonferroni
    # correction for what the sample effects' ranks already exercise)
    groups = int(np.shape(datasets.noise.calibration_members)[-1]) if model.scene.campaigns else 0
    for g in range(groups):
        truth[f"calibration_{g + 1}"] = np.empty(replicates)
        posterior[f"calibration_{g + 1}"] = np.empty_like(draws_tis)
    for r in range(replicates):
        data = jax.tree_util.tree_map(lambda leaf, r=r: leaf[r], datasets)
        true_sites = {k: np.asarray(v)[r][None, None] for k, v in simulated.items() if k != "obs"}
        effects, calibration = latent_effect_draws(model, true_sites, settings.seed + 7 * r, data)
        for g in range(groups):
            truth[f"calibration_{g + 1}"][r] = calibration[0, g]
        factor = target_log_factor("measured", effects, np.zeros(1), names)
        truth["tis70_measured"][r] = truth_tis[r] * np.exp(factor[0])
        tau = float(np.asarray(simulated["sample_sd"])[r])
        truth["tis70_new_part"][r] = truth_tis[r] * np.exp(tau * rng.standard_normal())
        own = {k: np.asarray(v)[r][None] for k, v in thinned.items()}
        effects, calibration = latent_effect_draws(inference, own, settings.seed + 7 * r + 3, data)
        for g in range(groups):
            posterior[f"calibration_{g + 1}"][r] = calibration[:, g]
        zeros = np.zeros(len(effects))
        factor = target_log_factor("measured", effects, zeros, names)
        posterior["tis70_measured"][r] = draws_tis[r] * np.exp(factor)
        new_part = own["sample_sd"][0] * rng.standard_normal(len(effects))
        posterior["tis70_new_part"][r] = draws_tis[r] * np.exp(new_part)
    return truth, posterior


def ranks_of(truth: dict[str, np.ndarray], posterior: dict[str, np.ndarray]) -> dict:
    """The rank of each truth among its replicate's draws (0 … draws), per quantity; a
    quantity the scene fixes (every draw equals the truth) is left out."""
    return {
        name: np.sum(posterior[name] < truth[name][:, None], axis=1)
        for name in truth
        if not _deterministic(truth[name], posterior[name])
    }


def run_sbc(
    scene: Scene,
    measurements: Measurements,
    settings: SbcSettings = SbcSettings(),
    *,
    model: str | None = None,
    progress: bool = False,
) -> SbcResult:
    """Simulation-based calibration of ``scene``'s posterior at its own geometry.

    Args:
        model: the BRDF family (default: the scene's ``[model] family``); its own generative
            model simulates the data and its posterior is checked.

    Raises:
        BadInputError: settings out of range, an unknown family, or a planted fault that does
            not apply (:func:`check_planted_fault`).
    """
    check_planted_fault(settings.planted_fault, scene, model)
    started = time.perf_counter()
    model = build_model(scene, measurements, model)
    inference = planted_inference(
        dataclasses.replace(model, sigma_scale=settings.sigma_scale), settings.planted_fault
    )
    simulated = simulate(model, settings.replicates, settings.seed)
    datasets = replicate_data(model.data, simulated["obs"])
    program = NutsProgram(
        inference,
        warmup=settings.warmup,
        target_accept=settings.target_accept,
        warmup_tree_depth=settings.warmup_tree_depth,
    )
    output = program.run_many(
        datasets,
        chain_keys(settings.seed + 1, settings.replicates, 1),
        settings.draws * settings.thin,
        progress=progress,
        description="SBC",
    )
    truth, posterior = ranked_quantities(model, simulated, output.sites, settings.thin)
    if model.errors.sample_effects and "tis70" in truth:
        target_truth, target_posterior = target_quantities(
            (model, inference), simulated, output.sites, datasets, settings
        )
        truth.update(target_truth)
        posterior.update(target_posterior)
    result = assess_ranks(settings, ranks_of(truth, posterior))
    return dataclasses.replace(
        result,
        divergences=np.sum(output.stats["diverging"], axis=(1, 2)),
        seconds=time.perf_counter() - started,
        compile_seconds=output.seconds["compile"],
    )


def check_planted_fault(fault: str | None, scene: Scene, model: str | None = None) -> None:
    """Check that ``fault`` is None or a key of :data:`~brdf_infer.scene.settings.PLANTED_FAULTS`
    that applies to the scene's posterior under the family ``model`` (default: the scene's).

    Raises:
        BadInputError: an unknown fault, or one the posterior has nothing to plant it in (another
            family; no free coefficient to whiten; no free parameter); field ``planted_fault``.
    """
    check_planted_fault_name(fault)
    if fault is None:
        return
    field = "planted_fault"
    name = scene.model.family if model is None else model
    check_family_name(name)
    if not family(name).paper_parameters:  # the faults are planted in Eq. (7)'s whitening
        raise BadInputError(
            f"planted fault {fault!r} is for the strumik2024 family, not {name}",
            field=field,
        )
    fixed = {name for name, prior in scene.priors.items() if prior.fixed}
    if fault == "jacobian" and fixed >= set(LINEAR):
        raise BadInputError(
            "planted fault 'jacobian' needs a free coefficient (brdf0, a1, a2, a3) to whiten",
            field=field,
        )
    if fault == "prior" and fixed >= set(scene.priors):
        raise BadInputError("planted fault 'prior' needs a free parameter", field=field)


def moved_prior(prior: Prior) -> Prior:
    """``prior`` moved up by one prior sd (a planted fault): loc + scale for the normal kinds
    (bounds kept), both bounds + (upper − lower)/√12 for a uniform; a fixed value stays."""
    if prior.kind in ("normal", "truncated_normal"):
        return dataclasses.replace(prior, loc=prior.loc + prior.scale)
    if prior.kind == "uniform":
        shift = (prior.upper - prior.lower) / np.sqrt(12.0)
        return dataclasses.replace(prior, lower=prior.lower + shift, upper=prior.upper + shift)
    return prior


def planted_inference(model: PosteriorModel, fault: str | None) -> PosteriorModel:
    """The model the inference runs with ``fault`` (a key of
    :data:`~brdf_infer.scene.settings.PLANTED_FAULTS`, checked by :func:`check_planted_fault`)
    planted; the simulations keep ``model``."""
    if fault == "jacobian":
        return dataclasses.replace(model, drop_log_jacobian=True)
    if fault == "prior":
        moved = {name: moved_prior(prior) for name, prior in model.scene.priors.items()}
        return dataclasses.replace(model, scene=dataclasses.replace(model.scene, priors=moved))
    return model


def _deterministic(truth: np.ndarray, draws: np.ndarray) -> bool:
    """A quantity every posterior draw of every replicate equals the truth of (fixed)."""
    return bool(np.all(draws == truth[:, None]))


def assess_ranks(settings: SbcSettings, ranks: dict[str, np.ndarray]) -> SbcResult:
    """χ², KS and coverage of the ranks (each in 0 … ``settings.draws``, one per replicate);
    the verdict at the family-wise level :data:`FAMILY_ALPHA`."""
    n, draws = settings.replicates, settings.draws
    rng = np.random.default_rng(settings.seed + 2)
    chi2_p, ks_p, coverage = {}, {}, {level: {} for level in COVERAGE_LEVELS}
    # each bin holds whole ranks, as evenly as they divide; its expected count is n times the
    # fraction of the L + 1 ranks it holds (equal widths on the real line would expect 10 where
    # 11.9 are due, and the χ² test rejected uniform ranks 1.6× as often as it should); fewer
    # bins for few replicates, so that each expects at least MIN_EXPECTED_PER_BIN (with 20 bins
    # and 10 or 20 replicates the verdict failed 1.7–1.8 % of null rank sets, not ≤ 1 %)
    bins = max(2, min(HISTOGRAM_BINS, draws + 1, n // MIN_EXPECTED_PER_BIN))
    expected = n * np.bincount(np.arange(draws + 1) * bins // (draws + 1)) / (draws + 1)
    names = list(ranks)
    table = np.stack([np.asarray(ranks[name]) for name in names]) if names else np.zeros((0, n))
    counts = np.stack([np.bincount(row * bins // (draws + 1), minlength=bins) for row in table])
    chi2 = stats.chisquare(counts, expected, axis=1).pvalue if names else []
    # the exact two-sided one-sample KS distribution (what ``stats.kstest`` uses for n ≤ 10⁴),
    # for every quantity at once
    randomised = np.sort((table + rng.uniform(size=table.shape)) / (draws + 1), axis=1)
    steps = np.arange(1, n + 1) / n
    distance = np.maximum(
        np.max(steps - randomised, axis=1), np.max(randomised - steps + 1 / n, axis=1)
    )
    ks = stats.kstwo.sf(distance, n) if names else []
    for k, name in enumerate(names):
        chi2_p[name] = float(chi2[k])
        ks_p[name] = float(np.clip(ks[k], 0.0, 1.0))
        fraction = table[k] / draws
        for level in COVERAGE_LEVELS:
            inside = (fraction >= (1 - level) / 2) & (fraction <= (1 + level) / 2)
            coverage[level][name] = float(np.mean(inside))
    threshold = FAMILY_ALPHA / (TESTS_PER_QUANTITY * len(ranks))
    coverage_range = {
        level: tuple(float(v) / n for v in stats.binom.interval(1 - threshold, n, level))
        for level in COVERAGE_LEVELS
    }
    failures = []
    for name in ranks:
        for test, p in (("chi2", chi2_p[name]), ("KS", ks_p[name])):
            if p < threshold:
                failures.append(f"{name}: {test} p = {p:.2g} < {threshold:.2g}")
        low, high = coverage_range[0.9]
        if not low <= coverage[0.9][name] <= high:
            failures.append(
                f"{name}: 90 % interval covers {coverage[0.9][name]:.1%}, outside "
                f"[{low:.1%}, {high:.1%}]"
            )
    return SbcResult(
        settings=settings,
        ranks=ranks,
        chi2_p=chi2_p,
        ks_p=ks_p,
        coverage=coverage,
        coverage_range=coverage_range,
        divergences=np.zeros(n, int),
        failures=failures,
        seconds=0.0,
        compile_seconds=0.0,
    )
