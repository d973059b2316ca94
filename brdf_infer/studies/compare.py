"""Model comparison by PSIS-LOO: is Eq. (7) better than the ray tracers' own scatter models?

Every family is sampled by NUTS on the same rows, under the same instrument (Eq. 6) and the
same generative error model; only the BRDF differs (one
:class:`brdf_infer.posterior.PosteriorModel` for every family).
Each row's pointwise log predictive density is that of its leave-one-out conditional
p(yᵢ | y₋ᵢ, θ) (the rows are correlated through the sample, calibration and angle effects;
:mod:`brdf_infer.posterior._loo`), and the run's own PSIS-LOO
(:func:`brdf_infer.posterior.psis_loo`, smoothed with the relative efficiency of the family's
draws) ranks the families: elpd_loo with its standard error, the difference to the best with
the standard error of the difference (Vehtari, Gelman & Gabry 2017, Eq. 24), stacking weights
(Yao et al. 2018), p_loo and the largest Pareto k: ArviZ's ``loo`` and ``compare`` of the same
terms give the same numbers (tested).

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
(:func:`brdf_infer.posterior.exact_loo_rows`, through the one refitter): at most five rows, a
refit whose chains diverge or disagree refused (the row keeps its PSIS term and its warning).
"""

from __future__ import annotations

import time
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
    ExactTerm,
    LeaveOneOut,
    NutsProgram,
    build_model,
    chain_keys,
    exact_loo_rows,
    flatten_draws,
    interval95,
    loo_terms,
    program_draws,
    psis_loo,
    rank_models,
    relative_efficiency,
)
from brdf_infer.runs.folder import COMPARE_FILE as COMPARE_FILE  # the old name, kept
from brdf_infer.scene import Scene
from brdf_infer.scene.settings import CompareSettings
from brdf_infer.tables.measurements import Measurements
from brdf_infer.verdict import PARETO_K_LIMIT as PARETO_K_LIMIT  # the old name, kept
from brdf_infer.verdict import limit_text

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
    output = program.run(
        model.data,
        chain_keys(settings.seed, 1, settings.chains)[0],
        settings.draws,
        progress=progress,
        description=f"NUTS {name}",
    )
    sites = output.sites
    log_lik = loo_terms(model, sites)[0]
    names = (*member.parameters, "sample_sd", "repeatability")
    idata = _idata(sites, log_lik, names)
    summary = az.summary(idata, var_names=[n for n in names if n in sites], kind="diagnostics")
    exact = {}
    if settings.refit:
        loo = _psis(idata)
        draws = program_draws(
            program, output, chains=settings.chains, draws=settings.draws, seed=settings.seed
        )
        terms = exact_loo_rows(model, draws, loo.pareto_k, loo.limit)
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


def _psis(idata: az.InferenceData) -> LeaveOneOut:
    """The run's PSIS-LOO (:func:`~brdf_infer.posterior.psis_loo`) of a family's stored
    leave-one-out terms, smoothed with the relative efficiency of its posterior's draws
    (:func:`~brdf_infer.posterior._loo.relative_efficiency`, as ArviZ's ``loo`` takes it)."""
    log_lik = np.asarray(idata.log_likelihood["obs"].values)
    return psis_loo(log_lik, None, relative_efficiency(idata.posterior))


def _elpd(fit: FamilyResult) -> LeaveOneOut:
    """The family's PSIS-LOO with the refitted rows' exact terms put in
    (:meth:`~brdf_infer.posterior.LeaveOneOut.with_exact`: elpd_loo, its se and p_loo = lppd −
    elpd_loo follow, lppd = Σᵢ ln mean_s of the pointwise terms over the full posterior, which
    the refits leave; the Pareto k stay the importance sampling's). The ranking reads the elpd
    terms only: the refits' LOO-PIT and Monte Carlo errors are not kept (NaN)."""
    nan = float("nan")
    return _psis(fit.idata).with_exact(
        {row: ExactTerm(value, nan, nan) for row, value in fit.exact_elpd.items()}
    )


def rank_families(fits: dict[str, FamilyResult]) -> tuple[list[dict[str, Any]], list[str]]:
    """The families ranked by elpd_loo (best first), with the difference of each to the best
    and its standard error (best − this, ≥ 0, as ArviZ's ``compare`` has ``elpd_diff``) and
    stacking weights (:func:`~brdf_infer.posterior._loo.rank_models`), and the warnings to
    show."""
    notes = []
    table = []
    for name, loo, d_elpd, dse, weight in rank_models({n: _elpd(f) for n, f in fits.items()}):
        fit = fits[name]
        refitted = np.isin(np.arange(loo.pareto_k.size), fit.refitted_rows)
        if fit.refitted_rows:
            notes.append(
                f"{name}: Pareto k > {limit_text(loo.limit)} for rows {fit.refitted_rows} "
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
                "elpd_loo": loo.elpd_loo,
                "se": loo.se,
                "d_elpd": d_elpd,
                "dse": dse,
                "weight": weight,
                "p_loo": loo.p_loo,
                "pareto_k_max": float(np.max(loo.pareto_k)),
                # a refitted row's term is exact: its k counts as 0
                "pareto_k_max_after_refit": float(np.max(np.where(refitted, 0.0, loo.pareto_k))),
                "pareto_k_limit": loo.limit,
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
