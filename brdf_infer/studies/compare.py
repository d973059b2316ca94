"""Model comparison by PSIS-LOO: is Eq. (7) better than the ray tracers' own scatter models?

Every family is sampled by NUTS on the same rows, under the same instrument (Eq. 6) and the
same generative error model; only the BRDF differs (one
:class:`brdf_infer.posterior.PosteriorModel` for every family).
Each row's pointwise log predictive density is that of its leave-one-out conditional
p(yᵢ | y₋ᵢ, θ) (the rows are correlated through the sample, calibration and angle effects;
:mod:`brdf_infer.posterior._loo`), and ArviZ's ``loo``/``compare`` rank the families: elpd_loo
with its standard error, the difference to the best with the standard error of the
difference, stacking weights, p_loo and the largest Pareto k.

Each family's sampler diagnostics stand next to its rank: a family whose NUTS run fails the
thresholds a posterior run is held to (R-hat ≤ 1.01, bulk ESS ≥ 400, no divergent
transitions; :data:`brdf_infer.posterior.THRESHOLDS`) is marked ``sampler_ok: false`` with the
failures in words, and its place in the ranking is not to be trusted: its elpd comes from draws
that may not represent its posterior.

Where Pareto k exceeds its limit (:func:`brdf_infer.verdict.pareto_k_limit` of the draws,
0.7 from 2200) the importance-sampling estimate of a row is unreliable; that row's
term is then computed exactly by refitting without it (leave-one-out by refit, i.e. K-fold
with one row per fold for those rows). Refitting needs no new compilation: the row is left
out by giving its measurement noise a σ of 10⁶ in ln R, which removes its information from
the likelihood while keeping the data's shape. The refits are the run's own
(:func:`brdf_infer.posterior.exact_loo`): at most five rows, a refit whose chains diverge or
disagree refused (the row keeps its PSIS term and its warning).
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer._internal import arviz as az
from brdf_infer._internal.precision import ensure_float64
from brdf_infer.errors import BadInputError
from brdf_infer.model import check_family_name
from brdf_infer.posterior import (
    THRESHOLDS,
    NutsProgram,
    build_model,
    chain_keys,
    exact_loo,
    flatten_draws,
    interval95,
    loo_terms,
    program_refit,
)
from brdf_infer.runs.folder import COMPARE_FILE as COMPARE_FILE  # the old name, kept
from brdf_infer.scene import Scene
from brdf_infer.scene.settings import CompareSettings
from brdf_infer.tables.measurements import Measurements
from brdf_infer.verdict import PARETO_K_LIMIT as PARETO_K_LIMIT  # the old name, kept
from brdf_infer.verdict import limit_text, pareto_k_limit

TIS_DRAWS = 400  # posterior draws the TIS band is computed from
TIS_ANGLE_DEG = 70.0


@dataclass
class FamilyResult:
    """One family's posterior summary and its leave-one-out terms.

    Attributes:
        name: the family.
        parameters: posterior median and 95 % interval of each physical parameter.
        tis70: median and 95 % interval of TIS(70°).
        idata: the physical parameters and noise scales (posterior) and the pointwise
            leave-one-out log likelihood (log_likelihood ``obs``: chains, draws, rows).
        r_hat_max, ess_bulk_min, divergences: NUTS diagnostics.
        refitted_rows: rows whose LOO term was computed by refitting (Pareto k above its limit).
        exact_elpd: the refitted rows' exact elpd terms.
        seconds: wall time of this family (sampling, refits and TIS).
    """

    name: str
    parameters: dict[str, dict[str, float]]
    tis70: dict[str, float]
    idata: az.InferenceData
    r_hat_max: float
    ess_bulk_min: float
    divergences: int
    refitted_rows: list[int]
    exact_elpd: dict[int, float]
    seconds: float

    @property
    def sampler_failures(self) -> list[str]:
        """The sampler diagnostics that failed their threshold, in words (empty: all pass)."""
        failures = []
        if not self.r_hat_max <= THRESHOLDS["r_hat"]:
            failures.append(f"R-hat {self.r_hat_max:.3f} > {THRESHOLDS['r_hat']}")
        if not self.ess_bulk_min >= THRESHOLDS["ess"]:
            failures.append(f"bulk ESS {self.ess_bulk_min:.0f} < {THRESHOLDS['ess']}")
        if self.divergences:
            failures.append(f"{self.divergences} divergent transitions")
        return failures


@dataclass
class ComparisonResult:
    """The ranking (``as_json`` gives the JSON contract of ``brdf-infer compare``)."""

    families: dict[str, FamilyResult]
    table: list[dict[str, Any]]
    warnings: list[str]
    seconds: float

    def as_json(self) -> dict[str, Any]:
        models = []
        for row in self.table:
            fit = self.families[row["name"]]
            models.append(
                {
                    **row,
                    "tis70": fit.tis70,
                    "parameters": fit.parameters,
                    "r_hat_max": fit.r_hat_max,
                    "ess_bulk_min": fit.ess_bulk_min,
                    "divergences": fit.divergences,
                    "sampler_ok": not fit.sampler_failures,
                    "sampler_failures": fit.sampler_failures,
                    "refitted_rows": fit.refitted_rows,
                }
            )
        return {"models": models, "warnings": self.warnings, "seconds": self.seconds}


def check_family_names(names: list[str]) -> list[str]:
    """Validated, de-duplicated family names (at least two).

    Raises:
        BadInputError: an unknown family, or fewer than two.
    """
    for name in names:
        check_family_name(name, field="models")
    names = list(dict.fromkeys(names))
    if len(names) < 2:
        raise BadInputError("name at least two families to compare", field="models")
    return names


def _idata(sites: dict, log_lik: np.ndarray, names: tuple[str, ...]) -> az.InferenceData:
    posterior = {name: sites[name] for name in names if name in sites}
    return az.from_dict(posterior=posterior, log_likelihood={"obs": log_lik})


def fit_family(
    scene: Scene,
    measurements: Measurements,
    name: str,
    settings: CompareSettings,
    *,
    progress: bool = False,
) -> FamilyResult:
    """Sample ``name`` on the scene's rows; leave-one-out terms, refits where k̂ exceeds its
    limit."""
    started = time.perf_counter()
    model = build_model(scene, measurements, name)
    member = model.products  # its TIS(70°) of the products' BRDF ([outputs] fold)
    program = NutsProgram(model, warmup=settings.warmup, target_accept=settings.target_accept)
    keys = chain_keys(settings.seed, 1, settings.chains)[0]
    output = program.run(
        model.data, keys, settings.draws, progress=progress, description=f"NUTS {name}"
    )
    sites = output.sites
    log_lik = loo_terms(model, sites)[0]
    names = (*member.parameters, "sample_sd", "repeatability")
    idata = _idata(sites, log_lik, names)
    summary = az.summary(idata, var_names=[n for n in names if n in sites], kind="diagnostics")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        loo = az.loo(idata, pointwise=True)
    exact = {}
    if settings.refit:
        rows = np.flatnonzero(np.asarray(loo.pareto_k) > pareto_k_limit(int(loo.n_samples)))
        terms = exact_loo(model, rows, program_refit(program, keys, settings.draws))
        exact = {row: term.elpd for row, term in terms.items()}
    refitted = sorted(exact)
    flat = flatten_draws({k: sites[k] for k in member.parameters})
    chosen = np.linspace(0, len(next(iter(flat.values()))) - 1, TIS_DRAWS).astype(int)
    physical = {k: jnp.asarray(v[chosen]) for k, v in flat.items()}
    tis70 = jax.jit(lambda p: member.tis_curve(jnp.array([TIS_ANGLE_DEG]), p))(physical)
    return FamilyResult(
        name=name,
        parameters={k: interval95(v) for k, v in flat.items()},
        tis70=interval95(np.asarray(tis70)),
        idata=idata,
        r_hat_max=float(np.max(summary["r_hat"])),
        ess_bulk_min=float(np.min(summary["ess_bulk"])),
        divergences=int(np.sum(output.stats["diverging"])),
        refitted_rows=refitted,
        exact_elpd=exact,
        seconds=time.perf_counter() - started,
    )


def _elpd(fit: FamilyResult):
    """ArviZ's PSIS-LOO of ``fit`` with the refitted rows' exact terms put in, and the
    largest Pareto k before the refits. ``p_loo`` follows the new elpd: ArviZ defines it as
    lppd − elpd_loo, with lppd = Σᵢ ln mean_s of the pointwise terms over the full posterior
    (here the leave-one-out conditionals p(yᵢ | y₋ᵢ, θ_s)), which the refits leave unchanged."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        loo = az.loo(fit.idata, pointwise=True)
    raw_k_max = float(np.max(np.asarray(loo.pareto_k)))
    if fit.exact_elpd:
        lppd = float(loo["p_loo"] + loo["elpd_loo"])
        pointwise = np.asarray(loo.loo_i).copy()
        for row, value in fit.exact_elpd.items():
            pointwise[row] = value
        loo.loo_i.values[:] = pointwise
        loo["elpd_loo"] = float(pointwise.sum())
        loo["p_loo"] = lppd - loo["elpd_loo"]
        loo["se"] = float(np.sqrt(pointwise.size * np.var(pointwise)))
        pareto_k = np.asarray(loo.pareto_k).copy()
        pareto_k[list(fit.exact_elpd)] = 0.0  # exact now
        loo.pareto_k.values[:] = pareto_k
        loo["warning"] = bool(np.any(pareto_k > pareto_k_limit(int(loo.n_samples))))
    return loo, raw_k_max


def rank_families(fits: dict[str, FamilyResult]) -> tuple[list[dict[str, Any]], list[str]]:
    """ArviZ ``compare`` of the families (best first) and the warnings to show."""
    elpds = {name: _elpd(fit) for name, fit in fits.items()}
    loos = {name: loo for name, (loo, _) in elpds.items()}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        frame = az.compare(loos, ic="loo", method="stacking")
    notes = []
    table = []
    for name, row in frame.iterrows():
        fit = fits[name]
        k_max = float(np.max(np.asarray(loos[name].pareto_k)))
        limit = pareto_k_limit(int(loos[name].n_samples))
        if fit.refitted_rows:
            notes.append(
                f"{name}: Pareto k > {limit_text(limit)} for rows {fit.refitted_rows} "
                "(LOO by refit there)"
            )
        if fit.sampler_failures:
            notes.append(
                f"{name}: sampler diagnostics fail ({', '.join(fit.sampler_failures)}): its "
                "place in the ranking is not to be trusted"
            )
        table.append(
            {
                "name": name,
                "elpd_loo": float(row["elpd_loo"]),
                "se": float(row["se"]),
                "d_elpd": float(row["elpd_diff"]),
                "dse": float(row["dse"]),
                "weight": float(row["weight"]),
                "p_loo": float(row["p_loo"]),
                "pareto_k_max": elpds[name][1],
                "pareto_k_max_after_refit": k_max,
                "pareto_k_limit": limit,
            }
        )
    return table, notes


def compare_families(
    scene: Scene,
    measurements: Measurements,
    names: list[str],
    settings: CompareSettings = CompareSettings(),
    *,
    progress: bool = False,
) -> ComparisonResult:
    """Fit every family in ``names`` by NUTS and rank them by PSIS-LOO (module docstring).

    Raises:
        BadInputError: unknown family names, fewer than two, or settings out of range.
    """
    ensure_float64()
    names = check_family_names(names)
    started = time.perf_counter()
    fits = {
        name: fit_family(scene, measurements, name, settings, progress=progress) for name in names
    }
    table, notes = rank_families(fits)
    return ComparisonResult(fits, table, notes, time.perf_counter() - started)
