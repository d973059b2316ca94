"""Whether the data reject the model: the checks of a run against its own rows.

Sampler diagnostics say whether the draws describe the posterior; they cannot say whether
the posterior's model describes the data. A run is therefore also judged by its rows, after
sampling, from what the run computed anyway (the leave-one-out predictive of every row,
:mod:`._loo`, and the draws):

* ``loo_pit``: the LOO-PIT values uᵢ = P(ỹᵢ ≤ yᵢ | y₋ᵢ) are uniform when the model is right;
  the Kolmogorov–Smirnov test of their uniformity (Gelman et al. 2013, *Bayesian Data
  Analysis*, Sec. 6.3; Säilynoja, Bürkner & Vehtari 2022, Stat. Comput. 32, 32) sees a
  predictive too narrow or too wide, and a misfit that makes the rows' scatter larger than
  the model allows.
* ``residual_trend``: the rows' residuals from the posterior median's prediction, whitened
  by the posterior's own covariance of the rows (each row's σ, the learned repeatability and
  sample scale, the calibration, the angle terms: D + W Wᵀ at the median), regressed on their
  θs, θi, series and sample (each a group of columns, :func:`row_groups`) beside what the
  parameters absorb (the Jacobian of the prediction in the free parameters): each group's
  F-test (:func:`brdf_infer.fit.quality.trend_tests`; the smallest p-value times the number
  of groups, :func:`~brdf_infer.fit.quality.worst_trend`, so that one group's misfit is
  judged on its own degrees of freedom, not diluted by the sample indicators') is exact for
  a model linear in its parameters with that covariance, whatever its overall scale, so a
  model whose shape does not follow the data fails it however much noise it learns to absorb
  the misfit. (Standardised *leave-one-out* residuals, Φ⁻¹ of the LOO-PIT, cannot serve: rows
  that share a sample or a calibration are negatively correlated given the others, which
  makes a test that takes them as independent blind to offsets of a group and conservative
  for the rest: p-values of 0.7–1.0 on eight simulations of a right model, a 30 % series
  offset never found.)
* ``at_bound``: a parameter whose posterior piles against a bound of its prior (more than
  half the draws within 2 % of the prior's central 95 % range of the bound): the data push
  it beyond what the prior or the family allows, the mark of a shape the model cannot take.

A check fails below :data:`CHECK_P_VALUE` (0.1 %; the run's checks together stay below
about 0.3 % false alarms on a right model). Each states what it could detect, computed for
the run's own rows (:func:`detectable_trends`, :func:`detectable_spread`): a check that
passes has not shown the model right, only that no misfit of that size is there.

The least-squares fit's own checks (:mod:`brdf_infer.fit.quality`), where the run has them
(``brdf-infer run``), join these as further entries of the same record; what to do next
(``brdf-infer compare``, a θs sign convention) comes with a failed record
(:func:`model_check`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from scipy import optimize, stats

from brdf_infer.fit.quality import (
    TREND_P_VALUE,
    LowRankNoise,
    detectable_trends,
    detectable_words,
    trend_regressors,
    trend_tests,
    worst_trend,
)
from brdf_infer.model import ModelFamily
from brdf_infer.model.priors import Prior
from brdf_infer.posterior._model import NOISE_SITES, PosteriorModel
from brdf_infer.predict.observations import log_reflectance
from brdf_infer.scene import BUILTIN_SCENES, Scene, scene_file
from brdf_infer.tables.measurements import Measurements
from brdf_infer.verdict.plausibility import mirrored_sign_words

CHECK_P_VALUE = TREND_P_VALUE  # a check fails below this p-value (0.1 %)
BOUND_FRACTION = 0.02  # of the prior's central 95 % range: "at" a bound
BOUND_PILED = 0.5  # the share of draws within it that makes a pile
# the Kolmogorov–Smirnov statistic √n D at p = CHECK_P_VALUE (Kolmogorov's distribution)
KS_CRITICAL = float(stats.kstwobign.isf(CHECK_P_VALUE))
# √n·D(f) at which that test finds rows scattering f times the predictive sd in 80 % of data
# sets: the critical value less 0.27 (simulated, 600 sets at each bisection step: 0.28, 0.26
# and 0.26 below it at 42, 200 and 1000 rows)
KS_POWER_OFFSET = 0.27
GROUP_WORDS = {"theta_s": "θs", "theta_i": "θi", "series": "series", "sample": "sample"}


def check(
    name: str,
    statistic: float | None,
    p: float | None,
    ok: bool,
    words: str,
    detectable: str,
) -> dict[str, Any]:
    """One entry of the ``model_check`` record: its ``name``, test ``statistic`` and ``p``
    (None where the check is no test), whether it passed, what it found in words and the
    misfit it could detect."""
    return {
        "name": name,
        "statistic": statistic,
        "p": p,
        "ok": bool(ok),
        "words": words,
        "detectable": detectable,
    }


def row_groups(measurements: Measurements) -> dict[str, np.ndarray]:
    """The trend groups of a run's rows: θs, θi and series (:func:`trend_regressors`) and
    the sample (one indicator per sample but the first; left out with one sample)."""
    groups = trend_regressors(
        measurements.theta_i_deg, measurements.theta_s_deg, np.asarray(measurements.series)
    )
    names = list(dict.fromkeys(np.asarray(measurements.sample).tolist()))
    if len(names) > 1:
        sample = np.asarray(measurements.sample)
        groups["sample"] = np.stack([sample == n for n in names[1:]], axis=1).astype(float)
    return groups


def ks_statistic(rows: int, factor: float) -> float:
    """√n·D, the Kolmogorov–Smirnov statistic of the LOO-PIT of ``rows`` rows whose scatter
    is ``factor`` times the predictive's (uᵢ = Φ(factor·Zᵢ)), at its expectation: √n times
    the largest distance between the uniform CDF and Φ(Φ⁻¹(u)/factor)."""
    u = np.linspace(1e-4, 1 - 1e-4, 4001)
    distance = np.max(np.abs(stats.norm.cdf(stats.norm.ppf(u) / factor) - u))
    return math.sqrt(rows) * float(distance)


def detectable_spread(rows: int) -> float:
    """The scatter factor f > 1 (rows scattering f times the predictive's sd) that the
    LOO-PIT's Kolmogorov–Smirnov test at :data:`CHECK_P_VALUE` detects with probability 0.8:
    where √n·D(f) reaches the critical value less :data:`KS_POWER_OFFSET` (the empirical CDF's
    noise raises the statistic above √n·D(f); tests/test_model_check.py measures the power by
    simulation). Infinite where no factor up to 50 reaches it."""
    target = KS_CRITICAL - KS_POWER_OFFSET
    if ks_statistic(rows, 50.0) < target:
        return math.inf
    return float(optimize.brentq(lambda f: ks_statistic(rows, f) - target, 1.0 + 1e-9, 50.0))


def loo_pit_check(pit: np.ndarray) -> dict[str, Any]:
    """The ``loo_pit`` check (module docstring): statistic the Kolmogorov–Smirnov D."""
    pit = np.asarray(pit, float)
    result = stats.kstest(pit, "uniform")
    p = float(result.pvalue)
    ok = p >= CHECK_P_VALUE
    spread = detectable_spread(pit.size)
    detectable = (
        f"rows scattering {spread:.2g} times the predictive sd"
        if math.isfinite(spread)
        else "nothing: too few rows"
    )
    if ok:
        words = (
            "no misfit detected in the leave-one-out predictive (LOO-PIT uniform within "
            f"chance, Kolmogorov–Smirnov p = {p:.2g})"
        )
    else:
        words = (
            f"the LOO-PIT is not uniform (Kolmogorov–Smirnov p = {p:.2g} < {CHECK_P_VALUE:g}): "
            "the predictive does not describe the rows it leaves out"
        )
    return check("loo_pit", float(result.statistic), p, ok, words, detectable)


def residual_trend_check(
    model: PosteriorModel, measurements: Measurements, sites: Mapping[str, np.ndarray]
) -> dict[str, Any]:
    """The ``residual_trend`` check (module docstring): statistic the joint F; what it could
    detect (:func:`~brdf_infer.fit.quality.detectable_trends`) in the rows' own noise, as a
    change of the measured value."""
    member = model.family
    point = {  # the posterior median of each quantity, as one draw
        name: np.median(np.reshape(values, (-1, *np.shape(values)[2:])), axis=0)[None]
        for name, values in sites.items()
        if name in (*member.parameters, *NOISE_SITES)
    }
    parts = model.draw_parts(point)
    data = model.data
    residuals = np.asarray(data.rows.log_reflectance - parts.mean[0], float)
    noise = LowRankNoise(np.asarray(parts.diagonal[0], float), np.asarray(parts.factor[0], float))
    free = [name for name in member.parameters if np.ptp(np.asarray(sites[name])) > 0]
    physical = {name: jnp.asarray(point[name][0]) for name in member.parameters}
    columns = jax.jacfwd(lambda p: log_reflectance(member, p, data.rows))(physical)
    absorbed = (  # draws all alike (no parameter moved): nothing is absorbed
        np.column_stack([np.asarray(columns[name], float) for name in free])
        if free
        else np.zeros((len(residuals), 0))
    )
    groups = row_groups(measurements)
    tests = trend_tests(residuals, noise, absorbed, groups) if groups else {}
    worst = worst_trend(tests)
    sizes = detectable_trends(noise, absorbed, groups, joint=False) if groups else {}
    detectable = detectable_words(sizes) or "nothing: no degrees of freedom"
    if worst is None:
        return check(
            "residual_trend", None, None, True, "not judged: no degrees of freedom", detectable
        )
    name, statistic, p = worst
    if p >= CHECK_P_VALUE:
        words = (
            "no trend detected in the standardised residuals with θs, θi, series or sample "
            f"(smallest p = {p:.2g}, {GROUP_WORDS[name]}, over the {len(groups)} groups)"
        )
        return check("residual_trend", statistic, p, True, words, detectable)
    words = (
        f"the standardised residuals trend with {GROUP_WORDS[name]} (p = {p:.2g} over the "
        f"{len(groups)} groups, < {CHECK_P_VALUE:g}): the model's shape does not follow the data"
    )
    return check("residual_trend", statistic, p, False, words, detectable)


def bounded_priors(scene: Scene, member: ModelFamily) -> list[tuple[str, str, Prior]]:
    """(site, name in words, prior) of every sampled quantity with a bounded prior: Eq. (7)'s
    α and θs0 under the scene's ``[priors]``, another family's coordinates under theirs."""
    if member.paper_parameters:
        words = {"alpha": "α", "theta_s0": "θs0"}
        return [
            (name, words[name], scene.priors[name])
            for name in ("alpha", "theta_s0")
            if not scene.priors[name].fixed and scene.priors[name].kind != "normal"
        ]
    return [(c.site, c.site, c.prior) for c in member.coordinates if c.prior.kind != "normal"]


def _central_range(prior: Prior) -> tuple[float, float]:
    """The prior's central 95 % interval."""
    if prior.kind == "uniform":
        span = prior.upper - prior.lower
        return prior.lower + 0.025 * span, prior.upper - 0.025 * span
    a, b = (prior.lower - prior.loc) / prior.scale, (prior.upper - prior.loc) / prior.scale
    low, high = stats.truncnorm.ppf([0.025, 0.975], a, b, loc=prior.loc, scale=prior.scale)
    return float(low), float(high)


def at_bound_check(
    scene: Scene, member: ModelFamily, sites: Mapping[str, np.ndarray]
) -> dict[str, Any]:
    """The ``at_bound`` check (module docstring): statistic the largest share of draws at a
    bound."""
    piled, largest = [], 0.0
    for site, words, prior in bounded_priors(scene, member):
        if site not in sites:
            continue
        draws = np.asarray(sites[site], float).reshape(-1)
        low, high = _central_range(prior)
        near = BOUND_FRACTION * (high - low)
        for side, bound in (("lower", prior.lower), ("upper", prior.upper)):
            if not math.isfinite(bound):
                continue
            share = float(np.mean(np.abs(draws - bound) <= near))
            largest = max(largest, share)
            if share > BOUND_PILED:
                piled.append(
                    f"{words} piles at the {side} bound of its prior ({bound:g}: "
                    f"{100 * share:.0f} % of the draws within {near:.2g} of it)"
                )
    detectable = (
        f"more than {100 * BOUND_PILED:.0f} % of the draws within {100 * BOUND_FRACTION:g} % "
        "of the prior's central 95 % range of a bound"
    )
    if not piled:
        return check(
            "at_bound",
            largest,
            None,
            True,
            "no parameter piles at a bound of its prior",
            detectable,
        )
    words = "; ".join(piled) + ": the data push it beyond what the model allows"
    return check("at_bound", largest, None, False, words, detectable)


def posterior_checks(
    model: PosteriorModel,
    measurements: Measurements,
    pit: np.ndarray,
    sites: Mapping[str, np.ndarray],
) -> list[dict[str, Any]]:
    """The checks a posterior run makes of its model against its rows (module docstring):
    ``pit`` the rows' LOO-PIT, ``sites`` the draws (chains, draws, ...)."""
    return [
        loo_pit_check(pit),
        residual_trend_check(model, measurements, sites),
        at_bound_check(model.scene, model.family, sites),
    ]


def model_check(
    checks: Sequence[dict[str, Any]], scene: Scene, measurements: Measurements
) -> dict[str, Any]:
    """The ``model_check`` record of a run of ``scene`` on ``measurements``: ``ok`` (every
    check passed), the ``checks`` and, where one failed, ``next``: what to try, most specific
    first (a θs sign convention the rows point to,
    :func:`~brdf_infer.verdict.plausibility.mirrored_sign_words`), then the comparison of the
    model families on these rows."""
    ok = all(entry["ok"] for entry in checks)
    record: dict[str, Any] = {"ok": ok, "checks": list(checks)}
    if not ok:
        name = scene_argument(scene)
        mirrored = mirrored_sign_words(measurements)
        record["next"] = [
            *([mirrored] if mirrored else []),
            f"compare the model families on these rows, `brdf-infer compare {name}` (PSIS-LOO "
            f"with its standard error), or let the run choose one: `brdf-infer run {name} "
            "--model auto`",
        ]
    return record


def scene_argument(scene: Scene) -> str:
    """How a command line names ``scene``: a built-in's name, else its file."""
    if scene.name in BUILTIN_SCENES and scene_file(scene.name) == scene.path:
        return scene.name
    return str(scene.path)
