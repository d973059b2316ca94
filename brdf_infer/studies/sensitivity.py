"""Sensitivity of the answer to the error model's assumptions: ``brdf-infer sensitivity``.

The error model (:mod:`brdf_infer.model.error_model`) rests on assumptions the data cannot settle
alone: which rows share a calibration, its size, what a sample-rotation error does to θs, how
many images were averaged into a row. This study samples the scene's posterior under its own
error model (the baseline) and under each *variant*, a set of ``[errors]`` keys changed
(``calibration=none``, ``rotation_coupling=camera_fixed``, ...), and reports for each the TIS
at the scene's angles and π·BRDF0 with 95 % intervals — what the assumption does to the
answer — and PSIS-LOO with its difference to the baseline, Δelpd ± se — what the data say
about it (more is better; a difference is clear when it is several times its se).

Every variant is sampled by the same NUTS settings from the same seed. The options that are
data of the compiled likelihood (:data:`brdf_infer.model.error_model.DATA_OPTIONS`) leave the model
structure as it is, so the variants of one structure share one compiled program, their data
padded to one shape (:mod:`brdf_infer.posterior._padding`: zero calibration columns add
nothing); another error model (``model=spread``) compiles its own.

Each row's pointwise log predictive density is that of its leave-one-out conditional
(:func:`brdf_infer.posterior.loo_terms`), and each posterior's PSIS-LOO is the run's
(:func:`brdf_infer.posterior.psis_loo`, smoothed with the relative efficiency of its draws);
where Pareto k exceeds its limit (:func:`brdf_infer.verdict.pareto_k_limit` of the draws) the
row's term is computed exactly by refitting without it, through the same program, by the
run's own exact LOO (:func:`brdf_infer.posterior.exact_loo_rows`: at most five rows, refits
that fail the one convergence rule refused), as the model comparison does. Δelpd and its se
are Vehtari, Gelman & Gabry's (2017) Eq. 24 (:func:`brdf_infer.posterior._loo.elpd_difference`).
The TIS follows the scene's ``[model] fold`` (its bands' convention).

The baseline posterior is also checked for its sensitivity to the prior and to the likelihood
by power-scaling (:func:`brdf_infer.posterior.power_scaling`): per free parameter, learned
noise scale and TIS(70°), how far the posterior would move if either were raised to a power
near 1.
"""

from __future__ import annotations

import dataclasses
import time
import tomllib
import warnings
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from brdf_infer.errors import BadInputError
from brdf_infer.model import family
from brdf_infer.model.error_model import CALIBRATIONS, ROTATION_COUPLINGS
from brdf_infer.runs.folder import SENSITIVITY_FIGURE as SENSITIVITY_FIGURE  # the old name, kept
from brdf_infer.runs.folder import SENSITIVITY_FILE as SENSITIVITY_FILE  # the old name, kept
from brdf_infer.scene import TIS_ANGLE_DEG, Scene, parse_errors, tis_angles
from brdf_infer.scene.settings import SensitivitySettings
from brdf_infer.tables.measurements import Measurements

if TYPE_CHECKING:  # ArviZ is imported where it is used: the command line's parser stays light
    from brdf_infer._internal.arviz import InferenceData

BASELINE = "default"


@dataclass(frozen=True)
class Variant:
    """A set of ``[errors]`` keys changed from the scene's (``name``: ``key=value, ...``)."""

    name: str
    changes: dict[str, Any] = field(default_factory=dict)


def _toml_value(value: Any) -> str:
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items()) + " }"
    if isinstance(value, bool):
        return "true" if value else "false"
    return f"{value:g}" if isinstance(value, float) else str(value)


def variant(changes: dict[str, Any]) -> Variant:
    """The variant that changes these keys (named after them)."""
    return Variant(", ".join(f"{k}={_toml_value(v)}" for k, v in changes.items()), dict(changes))


def _split_changes(spec: str) -> list[str]:
    """``KEY=VALUE`` parts of a variant spec, split at commas outside ``{ }``."""
    parts, depth, current = [], 0, ""
    for character in spec:
        depth += {"{": 1, "}": -1}.get(character, 0)
        if character == "," and depth == 0:
            parts.append(current)
            current = ""
        else:
            current += character
    return [*parts, current]


def _value(text: str) -> Any:
    """A TOML value (number, boolean, inline table) or, failing that, the bare string."""
    try:
        return tomllib.loads(f"value = {text}")["value"]
    except tomllib.TOMLDecodeError:
        return text.strip().strip('"')


def parse_variant(spec: str, scene: Scene) -> Variant:
    """A variant from ``KEY=VALUE[,KEY=VALUE...]`` (keys of ``[errors]``), checked against the
    scene as its own ``[errors]`` table would be.

    Raises:
        BadInputError: a part without ``=``, an unknown key, or a value out of range
            (field ``variants``).
    """
    changes = {}
    for part in _split_changes(spec):
        key, equals, text = part.partition("=")
        if not equals or not key.strip():
            raise BadInputError(
                f"{spec!r}: expected KEY=VALUE (keys of [errors], e.g. calibration=none)",
                field="variants",
            )
        changes[key.strip()] = _value(text.strip())
    named = variant(changes)
    variant_scene(scene, named)
    return named


def variant_scene(scene: Scene, changed: Variant, field_name: str = "variants") -> Scene:
    """``scene`` with the variant's ``[errors]`` keys changed, validated as a scene's table.

    Raises:
        BadInputError: an unknown key or a value out of range (naming the variant).
    """
    table = {**scene.errors.as_table(), **changed.changes}
    try:
        errors = parse_errors(table, scene.path, tuple(scene.series))
        errors = dataclasses.replace(errors, campaign_errors=scene.errors.campaign_errors)
    except BadInputError as error:
        raise BadInputError(
            f"variant {changed.name!r}: {error.field}: {error.problem}", field=field_name
        ) from None
    return dataclasses.replace(scene, errors=errors)


def default_variants(scene: Scene) -> list[Variant]:
    """The variants that change the answer's assumptions one at a time: the other calibration
    choices (where the calibration has a size), the other rotation coupling (where angle
    errors are on), one image per row and, where the scene's images differ by series, every
    series with the largest of them, and the other error model."""
    errors = scene.errors
    if errors.model == "spread":
        return [variant({"model": "generative"})]
    changes: list[dict[str, Any]] = []
    if errors.calibration_rel > 0:
        changes += [{"calibration": kind} for kind in CALIBRATIONS if kind != errors.calibration]
    if errors.angles_on:
        changes += [
            {"rotation_coupling": other}
            for other in ROTATION_COUPLINGS
            if other != errors.rotation_coupling
        ]
    counts = {errors.images_of(name) for name in scene.series}
    if counts != {1}:
        changes.append({"images_per_row": 1})
    if len(counts) > 1:
        changes.append({"images_per_row": max(counts)})
    changes.append({"model": "spread"})
    return [variant(c) for c in changes]


def check_scene(scene: Scene) -> None:
    """Refuse a scene the study cannot answer for: another family than ``strumik2024``
    (π·BRDF0 is its parameter) or no out-of-plane model (no TIS)."""
    if not family(scene.model.family).paper_parameters:
        raise BadInputError(
            "the sensitivity study samples strumik2024 (π·BRDF0 and the TIS of Eq. 9), "
            f"not {scene.model.family}",
            file=scene.path,
            field="model.family",
        )
    if not scene.model.out_of_plane:
        raise BadInputError(
            "the sensitivity study reports the TIS, which needs the out-of-plane model",
            file=scene.path,
            field="model.out_of_plane",
        )


@dataclass
class VariantResult:
    """One posterior of the study.

    Attributes:
        variant: what was changed (nothing for the baseline).
        tis: ``theta_i_deg``, ``median``, ``lo95``, ``hi95`` (lists over the angles).
        pi_brdf0: median and 95 % interval of π·BRDF0.
        elpd_loo, se: PSIS-LOO (exact where refitted) and its standard error.
        pointwise: each row's leave-one-out elpd term.
        diagnostics: ``r_hat_max``, ``ess_bulk_min``, ``divergences``, ``pareto_k_max``
            (before the refits), ``pareto_k_limit`` (that of the draws:
            :func:`~brdf_infer.verdict.pareto_k_limit`) and ``refitted_rows`` (0-based rows
            with Pareto k above it whose term is exact).
        idata: the posterior (free parameters, noise scales) and its leave-one-out log
            likelihood.
        seconds: wall time of this posterior (sampling and the summaries).
    """

    variant: Variant
    tis: dict[str, list[float]]
    pi_brdf0: dict[str, float]
    elpd_loo: float
    se: float
    pointwise: np.ndarray
    diagnostics: dict[str, float]
    idata: InferenceData
    seconds: float

    def as_json(self, baseline: VariantResult) -> dict[str, Any]:
        """The contract's entry: Δelpd and its se against ``baseline`` (pointwise)."""
        from brdf_infer.posterior import elpd_difference

        d_elpd, dse = elpd_difference(self.pointwise, baseline.pointwise)
        return {
            "name": self.variant.name,
            "changes": self.variant.changes,
            "tis": self.tis,
            "pi_brdf0": self.pi_brdf0,
            "elpd_loo": self.elpd_loo,
            "d_elpd": d_elpd,
            "dse": dse,
            "diagnostics": self.diagnostics,
        }


@dataclass
class SensitivityResult:
    """The study (``as_json``: the JSON of ``brdf-infer sensitivity --json``).

    Attributes:
        baseline: the posterior under the scene's error model.
        variants: the posterior under each variant, in the order asked.
        power_scaling: the baseline's prior and likelihood sensitivity per quantity
            (``{name: {"prior", "likelihood", "diagnosis"}}``).
        seconds: wall time of the study.
    """

    baseline: VariantResult
    variants: list[VariantResult]
    power_scaling: dict[str, dict[str, float | str]]
    seconds: float

    def as_json(self) -> dict[str, Any]:
        return {
            "baseline": self.baseline.as_json(self.baseline),
            "variants": [v.as_json(self.baseline) for v in self.variants],
            "power_scaling": self.power_scaling,
            "seconds": self.seconds,
        }


def _summarise(
    changed: Variant,
    model,
    draws,
    angles: list[float],
    started: float,
    refit: bool,
) -> VariantResult:
    """TIS, π·BRDF0, PSIS-LOO (exact by refit where k̂ exceeds its limit, with ``refit``) and
    the sampler's health of one variant's draws (:class:`~brdf_infer.posterior.Draws` of its
    program)."""
    from brdf_infer._internal import arviz as az
    from brdf_infer.posterior import (
        FAMILY_TIS_DRAWS,
        NOISE_SITES,
        draws_physical,
        exact_loo_rows,
        interval95,
        loo_terms,
        psis_loo,
        relative_efficiency,
        tis_band,
    )

    sites = draws.sites
    log_lik, cdf = loo_terms(model, sites)
    names = [*model.scene.free_parameters, *(n for n in NOISE_SITES if n in sites)]
    idata = az.from_dict(
        posterior={name: sites[name] for name in names},
        log_likelihood={"obs": log_lik},
        sample_stats={"diverging": draws.stats["diverging"]},
    )
    with warnings.catch_warnings():  # a high Pareto k is reported in the diagnostics
        warnings.simplefilter("ignore")
        summary = az.summary(idata, var_names=names, kind="diagnostics", round_to="none")
    loo = psis_loo(log_lik, cdf, relative_efficiency(idata.posterior))
    exact = exact_loo_rows(model, draws, loo.pareto_k, loo.limit) if refit else {}
    refitted = loo.with_exact(exact)
    physical = draws_physical(sites, model.family)
    band = tis_band(model.family, physical, angles, FAMILY_TIS_DRAWS)
    return VariantResult(
        variant=changed,
        tis={key: band[key] for key in ("theta_i_deg", "median", "lo95", "hi95")},
        pi_brdf0=interval95(np.pi * physical["brdf0"]),
        elpd_loo=refitted.elpd_loo,
        se=refitted.se,
        pointwise=refitted.elpd_i,
        diagnostics={
            "r_hat_max": float(np.max(summary["r_hat"])),
            "ess_bulk_min": float(np.min(summary["ess_bulk"])),
            "divergences": int(np.sum(draws.stats["diverging"])),
            "pareto_k_max": float(np.max(loo.pareto_k)),
            "pareto_k_limit": loo.limit,
            "refitted_rows": sorted(exact),
        },
        idata=idata,
        seconds=time.perf_counter() - started,
    )


def _power_scaling(scene: Scene, model, sites: dict[str, np.ndarray]) -> dict:
    """Power-scaling sensitivity of the free parameters (paper units), the learned noise
    scales and TIS(70°) of one posterior."""
    from brdf_infer.posterior import NOISE_SITES, draws_physical, power_scaling

    shape = np.shape(sites["alpha"])
    member = model.products  # the products' TIS, each draw's out-of-plane width
    values = np.exp(member.log_tis_draws(np.array([TIS_ANGLE_DEG]), draws_physical(sites, member)))
    quantities = {name: sites[name] for name in scene.free_parameters}
    quantities |= {name: sites[name] for name in NOISE_SITES if name in sites}
    quantities["tis_70deg"] = np.asarray(values).reshape(shape)
    return power_scaling(model, sites, quantities)


def sensitivity(
    scene: Scene,
    measurements: Measurements,
    variants: list[Variant] | None = None,
    settings: SensitivitySettings = SensitivitySettings(),
    *,
    progress: bool = False,
) -> SensitivityResult:
    """The scene's posterior under its own error model and under each variant (module
    docstring).

    Args:
        scene: the scene (``strumik2024`` with the out-of-plane model).
        measurements: its rows.
        variants: what to change (default :func:`default_variants`); each is checked against
            the scene before any sampling.
        settings: NUTS settings, the same for every posterior.
        progress: a progress bar per posterior on stderr.

    Raises:
        BadInputError: a scene the study cannot answer for, a variant that is not a valid
            ``[errors]`` table, or settings out of range.
    """
    from brdf_infer.posterior import (
        build_posterior_model,
        chain_keys,
        program_draws,
        programs_by_structure,
    )

    check_scene(scene)
    started = time.perf_counter()
    runs = [Variant(BASELINE), *(default_variants(scene) if variants is None else variants)]
    scenes = [variant_scene(scene, run) for run in runs]
    models = [build_posterior_model(s, measurements) for s in scenes]
    keys = chain_keys(settings.seed, 1, settings.chains)[0]
    angles = tis_angles(scene, measurements)
    results: list[VariantResult | None] = [None] * len(runs)
    scaling: dict = {}
    grouped = programs_by_structure(
        models, warmup=settings.warmup, target_accept=settings.target_accept
    )
    for program, members in grouped:
        for index, data in members:
            clock = time.perf_counter()
            output = program.run(
                data, keys, settings.draws, progress=progress, description=runs[index].name
            )
            model = dataclasses.replace(models[index], data=data)
            draws = program_draws(
                program, output, chains=settings.chains, draws=settings.draws, seed=settings.seed
            )
            results[index] = _summarise(runs[index], model, draws, angles, clock, settings.refit)
            if index == 0:
                scaling = _power_scaling(scene, model, output.sites)
    return SensitivityResult(results[0], results[1:], scaling, time.perf_counter() - started)
