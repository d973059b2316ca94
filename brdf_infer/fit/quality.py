"""How well a least-squares fit describes its data, judged against the data, stated next to
its result.

χ² = Σ rᵢ² of the weighted residuals follows a χ² distribution with dof = n − p degrees of
freedom when the model is right and the σᵢ are the rows' true noise. Where the σᵢ are taken
as given (the repeatability fixed, or the ``spread`` error model), the fit is **poor** when
both

- χ²/dof > :data:`POOR_CHI2_DOF` = 2: the 1σ from (JᵀJ)⁻¹, which takes the σᵢ at their word,
  then understates the parameters' scatter by more than √2 (41 %), and
- the upper-tail p-value of χ² is below :data:`POOR_P_VALUE` = 0.001: the excess is not the
  chance of a small dof (for the 36 dof of the bundled scene χ²/dof = 2 has p = 3·10⁻⁴; for
  5 dof it has p = 0.075 and is not called poor).

Where the error model learns the repeatability, least squares sets σ_rep so that χ²/dof = 1
(Paule–Mandel, :mod:`brdf_infer.fit.lsq`), and the χ² test says nothing; the misfit shows in σ_rep
instead. Least squares treats the rows as independent, so its σ_rep holds every scatter beyond
the rows' own σ and the angle terms: the repeatability, and the sample and calibration scatter
it does not model. The scene states what the instrument is known to reach in the same terms,
``[errors] expected_repeatability`` (the article's 6.5 % for the bundled data), and the fit is
then **poor** when σ_rep's 95 % interval lies wholly above :data:`POOR_MULTIPLE` = 2 times it
(:func:`repeatability_check`). The interval is the Q-profile interval of the Paule–Mandel
estimate (Viechtbauer 2007, Stat. Med. 26, 37): the s where Q(s) = Σ rᵢ²/(vᵢ + s²) equals the
2.5 % and 97.5 % points of χ²_dof, exact for a linear model with Gaussian rows. The factor 2
leaves room for the sample and calibration scatter σ_rep also holds, at the sizes the article
shows (the inter-sample spread of Sec. 5.3, calibration 6.5 % per series): a model's own misfit
must add √(2² − 1) ≈ 1.7 times the expected scatter (11 % for 6.5 %) before it can be seen.
On the bundled rows Eq. (7) learns 0.057 (95 % 0.028–0.11: ok); data simulated from the
generative model with a further 28 % lognormal misfit per row (a vendor table's scatter about
its model) learn 0.30 (median of 20; lower end 0.24 > 0.13: poor, all 20); ABg learns 1.88
(1.5–2.4: poor): one value at specular for every θi cannot follow data that grow 100-fold
there.

Every fit is also judged by the structure of its residuals (:func:`residual_trends`): a model
that is wrong in shape leaves residuals that trend with the angles or differ between series,
however small σ_rep is. The residuals are regressed on θs, θi and the series (each a group of
columns) beside what the fitted parameters can absorb (the linearised fit), with the rows
whitened by the noise least squares weights them by plus the calibration factors the scene
states (a series offset the calibration explains is not a misfit); the F-test of all the trend
columns together is scale-free, so it holds whatever σ_rep is. The fit is **poor** when its
p-value is below :data:`TREND_P_VALUE` = 0.001. The whitening is the error model's covariance
as least squares knows it (each row's σ, its rotation term shared by the rows of one rotation
setting, the calibration factors); the sample effect, whose scale the scene does not state, is
left out, which makes the test somewhat liberal where one series is one sample.

What each check could detect is stated beside its result (:func:`detectable_trends`: the
smallest trend or offset its F-test finds with 80 % power at p < 0.001, from the noncentral F
of the rows' own design), so that "no misfit detected" says how large a misfit went unseen.
The checks also enter a posterior run's ``model_check`` record (:meth:`FitQuality.model_checks`;
:mod:`brdf_infer.posterior`), beside the posterior's own checks of its leave-one-out
predictive.

Every fit also gives its 1σ scaled by √(χ²/dof) (the Birge ratio), the uncertainty the
parameters would have if the misfit were noise the σᵢ left out. A poor fit's scaled 1σ is
still a statement about a model that does not describe the data: a comparison by the data
(``brdf-infer compare``) is the better judge of such a model.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
from scipy.optimize import brentq
from scipy.stats import chi2 as chi2_distribution
from scipy.stats import f as f_distribution
from scipy.stats import ncf

POOR_CHI2_DOF = 2.0
POOR_P_VALUE = 1e-3
INTERVAL_LEVEL = 0.95  # of the learned repeatability's Q-profile interval
POOR_MULTIPLE = 2.0  # σ_rep's interval wholly above this × the expected repeatability: poor
TREND_P_VALUE = 1e-3  # the joint F-test of residual trends below this: poor
DETECTION_POWER = 0.8  # what a check could detect is stated at this power
TREND_GROUPS = ("theta_s", "theta_i", "series")


class RepeatabilityCheck(NamedTuple):
    """A learned repeatability against the expected one (:func:`repeatability_check`).

    Attributes:
        low, high: the Q-profile interval of σ_rep at :data:`INTERVAL_LEVEL` [ln R].
        p_value: P(Q ≥ Q(line)) under χ²_dof, the one-sided p-value of "σ_rep is at most
            :data:`POOR_MULTIPLE` × the expected": below (1 − level)/2 exactly when the
            interval lies wholly above that line.
    """

    low: float
    high: float
    p_value: float


def _q_root(residuals: np.ndarray, variances: np.ndarray, target: float) -> float:
    """The s ≥ 0 with Σ rᵢ²/(vᵢ + s²) = ``target`` (0 where Q(0) ≤ target)."""
    from brdf_infer.fit._reweighting import paule_mandel

    return paule_mandel(residuals, variances, target)


def q_statistic(residuals: np.ndarray, variances: np.ndarray, s: float) -> float:
    """Q(s) = Σ rᵢ²/(vᵢ + s²), the generalised Q of Paule–Mandel (decreasing in s)."""
    residuals, variances = np.asarray(residuals, float), np.asarray(variances, float)
    return float(np.sum(residuals**2 / (variances + s**2)))


def repeatability_check(
    residuals: np.ndarray, variances: np.ndarray, dof: int, expected: float
) -> RepeatabilityCheck:
    """The Q-profile interval of a Paule–Mandel σ_rep and its p-value against the poor line.

    Args:
        residuals: ln R residuals of the fit (model − data) [ln R].
        variances: each row's variance besides σ_rep (its value's and the angle terms) [ln R²].
        dof: rows − free parameters.
        expected: the scene's expected repeatability [ln R]; the line is
            :data:`POOR_MULTIPLE` × it.
    """
    tail = (1.0 - INTERVAL_LEVEL) / 2
    low = _q_root(residuals, variances, float(chi2_distribution.isf(tail, dof)))
    high = _q_root(residuals, variances, float(chi2_distribution.ppf(tail, dof)))
    line = POOR_MULTIPLE * expected
    p_value = float(chi2_distribution.sf(q_statistic(residuals, variances, line), dof))
    return RepeatabilityCheck(low, high, p_value)


def trend_regressors(
    theta_i_deg: np.ndarray, theta_s_deg: np.ndarray, series: np.ndarray
) -> dict[str, np.ndarray]:
    """The columns of each trend group (:data:`TREND_GROUPS`): θs and θi (one column each,
    linear) and the series (one indicator per series but the first); a group without
    variation among the rows is left out."""
    groups = {}
    for name, values in (("theta_s", theta_s_deg), ("theta_i", theta_i_deg)):
        values = np.asarray(values, float)
        if np.ptp(values) > 0:
            groups[name] = ((values - values.mean()) / np.ptp(values))[:, None]
    names = list(dict.fromkeys(np.asarray(series).tolist()))
    if len(names) > 1:
        series = np.asarray(series)
        groups["series"] = np.stack([series == n for n in names[1:]], axis=1).astype(float)
    return groups


def _residual_sum(design: np.ndarray, y: np.ndarray) -> tuple[float, int]:
    """Σ of the squared residuals of ``y`` regressed on ``design``, and the design's rank."""
    norms = np.linalg.norm(design, axis=0)
    design = design[:, norms > 0] / norms[norms > 0]
    if design.shape[1] == 0:
        return float(y @ y), 0
    u, s, _ = np.linalg.svd(design, full_matrices=False)
    basis = u[:, s > s[0] * 1e-9]
    left = y - basis @ (basis.T @ y)
    return float(left @ left), basis.shape[1]


class LowRankNoise(NamedTuple):
    """A rows' noise covariance D + W Wᵀ held as its parts (never rows × rows).

    Attributes:
        diagonal: D, each row's own variance (rows,) [ln R²].
        factor: W, one column per shared effect (rows × effects) [ln R].
    """

    diagonal: np.ndarray
    factor: np.ndarray

    def dense(self) -> np.ndarray:
        """D + W Wᵀ (rows × rows; small tables only)."""
        return np.diag(self.diagonal) + self.factor @ self.factor.T


def _low_rank_whitener(noise: LowRankNoise):
    """a → A a with Aᵀ A = (D + W Wᵀ)⁻¹, in O(rows × effects²) time and memory: with
    V = D^(-1/2) W = Q S Pᵀ (thin SVD), (I + V Vᵀ)^(-1/2) = I + Q ((1 + S²)^(-1/2) − 1) Qᵀ and
    A = (I + V Vᵀ)^(-1/2) D^(-1/2) (a symmetric square root; any A with that Gram gives the
    same generalised least squares)."""
    scale = 1.0 / np.sqrt(np.asarray(noise.diagonal, float))
    factor = np.asarray(noise.factor, float) * scale[:, None]
    if factor.shape[1] == 0:
        return lambda a: scale.reshape((-1,) + (1,) * (np.ndim(a) - 1)) * np.asarray(a, float)
    basis, values, _ = np.linalg.svd(factor, full_matrices=False)
    shrink = 1.0 / np.sqrt(1.0 + values**2) - 1.0

    def whiten(a):
        a = scale.reshape((-1,) + (1,) * (np.ndim(a) - 1)) * np.asarray(a, float)
        projected = basis.T @ a
        return a + basis @ (shrink.reshape((-1,) + (1,) * (np.ndim(a) - 1)) * projected)

    return whiten


def _whitener(noise: np.ndarray | LowRankNoise):
    """A map a → L⁻¹ a with L Lᵀ the covariance (a dense one, or D + W Wᵀ with D > 0 held as
    :class:`LowRankNoise`); for a singular covariance (rows that share every noise source,
    e.g. one incidence angle of one sample, no row noise of their own) the map onto its range,
    eigenvalues below 1e-12 of the largest left out (fewer rows then count)."""
    if isinstance(noise, LowRankNoise):
        if np.all(np.asarray(noise.diagonal) > 0):
            return _low_rank_whitener(noise)
        noise = noise.dense()
    covariance = np.asarray(noise, float)
    try:
        factor = np.linalg.cholesky(covariance)
    except np.linalg.LinAlgError:
        values, vectors = np.linalg.eigh(covariance)
        keep = values > 1e-12 * values.max()
        basis = (vectors[:, keep] / np.sqrt(values[keep])).T
        return lambda a: basis @ np.asarray(a, float)
    return lambda a: np.linalg.solve(factor, np.asarray(a, float))


def residual_trends(
    residuals: np.ndarray,
    covariance: np.ndarray | LowRankNoise,
    absorbed: np.ndarray,
    regressors: Mapping[str, np.ndarray],
) -> dict[str, float]:
    """F-test p-values of trends of a fit's residuals: each group of ``regressors`` alone and
    all together (``"joint"``), beside a constant and what the fit absorbs.

    The linearised fit: the residuals r are the data less a combination of the columns of
    ``absorbed`` (ln R per unit of each free parameter, rows × free). With the rows whitened by
    the Cholesky factor L of ``covariance`` (the noise the test takes as known in shape, its
    scale free), r is regressed on [1, absorbed] and on [1, absorbed, trend columns]; F = (drop
    of the residual sum / added rank) / (residual sum / (rows − rank)) follows F(added rank,
    rows − rank) for a right model with Gaussian noise of that covariance, whatever its scale.

    Args:
        residuals: ln R residuals (model − data) [ln R].
        covariance: the rows' noise covariance [ln R²], e.g. diag(σᵢ²) plus the calibration
            factors: rows × rows, or its parts (:class:`LowRankNoise`, linear in the rows).
        absorbed: the fit's Jacobian of ln R in its free parameters, or any basis of its
            column space.
        regressors: name → trend columns (rows × k), e.g. :func:`trend_regressors`.

    Returns:
        name → p-value for every group and ``"joint"`` (NaN where a group adds no rank or no
        degrees of freedom are left).
    """
    return {
        name: p for name, (_, p) in trend_tests(residuals, covariance, absorbed, regressors).items()
    }


def trend_tests(
    residuals: np.ndarray,
    covariance: np.ndarray | LowRankNoise,
    absorbed: np.ndarray,
    regressors: Mapping[str, np.ndarray],
) -> dict[str, tuple[float, float]]:
    """:func:`residual_trends` with each test's F statistic: name → (F, p-value), NaN both
    where a group adds no rank or no degrees of freedom are left."""
    whiten = _whitener(covariance)
    y = whiten(residuals)
    rows = len(y)
    base = whiten(np.column_stack([np.ones(len(residuals)), np.asarray(absorbed, float)]))
    base_sum, base_rank = _residual_sum(base, y)

    def test(columns: list[np.ndarray]) -> tuple[float, float]:
        full_sum, full_rank = _residual_sum(np.column_stack([base, *map(whiten, columns)]), y)
        added, left = full_rank - base_rank, rows - full_rank
        if added <= 0 or left <= 0 or full_sum <= 0:
            return math.nan, math.nan
        statistic = ((base_sum - full_sum) / added) / (full_sum / left)
        return float(statistic), float(f_distribution.sf(statistic, added, left))

    found = {name: test([columns]) for name, columns in regressors.items()}
    found["joint"] = test(list(regressors.values())) if regressors else (math.nan, math.nan)
    return found


def trend_repeatability(
    residuals: np.ndarray,
    noise: LowRankNoise,
    absorbed: np.ndarray,
    regressors: Mapping[str, np.ndarray],
) -> float:
    """The repeatability s ≥ 0 of the trend tests' whitening: the s at which the rows, with
    covariance ``noise`` + s² on its diagonal, leave a whitened residual sum of squares equal
    to its degrees of freedom after the regression on a constant, ``absorbed`` and every
    group of ``regressors`` (the joint test's full model); 0 where ``noise`` alone leaves less.

    :func:`trend_tests`' F-test takes the covariance as known in shape and estimates its scale
    from the full model's residuals, so every part of it scales together, the stated
    calibration factors too. A repeatability learned with the rows independent (least squares'
    Paule–Mandel σ_rep) also holds the calibration and sample scatter between series and any
    misfit, a series offset most of all; the whitened residuals then come out smaller than
    1, the test shrinks the calibration allowance by as much, and a series offset of 0.38 of
    the stated detectable size was found in half of the model-check power benchmark's data
    sets. Learned here, beside the trend columns and with the calibration in the covariance,
    the repeatability holds only the scatter within series, the whitened scale is 1 and the
    noncentral F of :func:`detectable_trends` describes the test
    (tests/test_model_check.py).

    Args:
        residuals: ln R residuals (model − data) [ln R].
        noise: the rows' covariance without the repeatability [ln R²] (each row's own and
            angle terms on ``diagonal``, > 0; shared effects in ``factor``).
        absorbed, regressors: as :func:`trend_tests`.
    """
    residuals = np.asarray(residuals, float)
    rows = len(residuals)
    diagonal = np.asarray(noise.diagonal, float)
    columns = [np.ones(rows), np.asarray(absorbed, float).reshape(rows, -1)]
    columns += [np.asarray(g, float).reshape(rows, -1) for g in regressors.values()]
    design = np.column_stack(columns)

    def excess(s: float) -> float:
        whiten = _whitener(LowRankNoise(diagonal + s**2, noise.factor))
        left_sum, rank = _residual_sum(whiten(design), whiten(residuals))
        return left_sum / (rows - rank) - 1.0 if rows > rank else -1.0

    if excess(0.0) <= 0.0:
        return 0.0
    high = max(float(np.std(residuals)), float(np.sqrt(np.median(diagonal))), 1e-6)
    for _ in range(60):
        if excess(high) < 0.0:
            break
        high *= 2.0
    return float(brentq(excess, 0.0, high, xtol=1e-9, rtol=1e-10))


def detectable_trends(
    covariance: np.ndarray | LowRankNoise,
    absorbed: np.ndarray,
    regressors: Mapping[str, np.ndarray],
    level: float = TREND_P_VALUE,
    power: float = DETECTION_POWER,
    joint: bool = True,
) -> dict[str, float]:
    """The smallest misfit of each group's kind that the trend test detects with probability
    ``power`` at ``level``, in the residuals' units (ln R for a fit's): for θs and θi the
    difference between the ends of the measured range of a linear trend (their columns run
    from −½ to ½), for series and sample an offset of one group against the first. The test:
    the F-test of all ``regressors`` together (``joint``, :func:`trend_tests`' ``"joint"``),
    else each group's own F-test at ``level`` / (number of groups) (:func:`worst_trend`).

    A misfit d·x (x the group's first column) moves the whitened residuals by d·L⁻¹x; the F
    statistic then has noncentrality λ = d² ‖P⊥ L⁻¹x‖², P⊥ the projection off the whitened
    base columns (a constant and ``absorbed``), so d = √(λ_p / ‖P⊥ L⁻¹x‖²), λ_p the
    noncentrality at which the noncentral F(k, n − m − k) exceeds its critical value with
    probability ``power`` (tests/test_model_check.py measures it by simulation).
    """
    whiten = _whitener(covariance)
    rows = np.shape(absorbed)[0]
    base = _orthonormal(whiten(np.column_stack([np.ones(rows), np.asarray(absorbed, float)])))
    columns = {name: whiten(np.asarray(g, float)) for name, g in regressors.items()}
    if not columns:
        return {}
    tested = [list(columns.values())] if joint else [[c] for c in columns.values()]
    each_level = level if joint else level / len(columns)
    found = {}
    for name, group in columns.items():
        own = tested[0] if joint else [group]
        added = _orthonormal(np.column_stack([base, *own])).shape[1] - base.shape[1]
        left = rows - base.shape[1] - added
        if added <= 0 or left <= 0:
            continue
        lam = noncentrality(added, left, each_level, power)
        x = group[:, 0]
        orthogonal = x - base @ (base.T @ x)
        size = float(orthogonal @ orthogonal)
        if size > 1e-12 * float(x @ x):
            found[name] = math.sqrt(lam / size)
    return found


def noncentrality(added: int, left: int, level: float, power: float) -> float:
    """The noncentrality λ at which the F-test of (``added``, ``left``) degrees of freedom at
    ``level`` rejects with probability ``power`` (noncentral F)."""
    critical = f_distribution.isf(level, added, left)
    return float(brentq(lambda value: ncf.sf(critical, added, left, value) - power, 1e-6, 1e8))


def worst_trend(tests: Mapping[str, tuple[float, float]]) -> tuple[str, float, float] | None:
    """The group whose own F-test (:func:`trend_tests`) has the smallest p-value: (its name,
    its F, that p-value × the number of groups, at most 1: Bonferroni over the groups, so that
    one group's misfit — a series offset, a θs trend — is judged on its own degrees of freedom
    rather than diluted among all); None where no group was tested."""
    groups = {name: test for name, test in tests.items() if name != "joint"}
    judged = {name: test for name, test in groups.items() if not math.isnan(test[1])}
    if not judged:
        return None
    name = min(judged, key=lambda n: judged[n][1])
    statistic, p = judged[name]
    return name, statistic, min(1.0, p * len(groups))


def _orthonormal(columns: np.ndarray) -> np.ndarray:
    """An orthonormal basis of the span of ``columns`` (norm-scaled; singular values below
    1e-9 of the largest left out)."""
    norms = np.linalg.norm(columns, axis=0)
    columns = columns[:, norms > 0] / norms[norms > 0]
    if columns.shape[1] == 0:
        return columns
    u, s, _ = np.linalg.svd(columns, full_matrices=False)
    return u[:, s > s[0] * 1e-9]


def detectable_words(sizes: Mapping[str, float], scale: float = 1.0) -> str:
    """Detectable misfits [ln R] (:func:`detectable_trends`, times ``scale``) in words, as
    changes of the measured value in %."""
    words = {"theta_s": "a θs trend", "theta_i": "a θi trend", "series": "a series offset"}
    words["sample"] = "a sample offset"
    return ", ".join(
        f"{words[name]} of {100 * math.expm1(size * scale):.2g} %"
        if size * scale < ABSORBED
        else f"no {words[name].removeprefix('a ')} (the fitted parameters absorb one)"
        for name, size in sizes.items()
    )


ABSORBED = math.log(10.0)  # a detectable size beyond ×10: the parameters absorb such a misfit


def detectable_scatter(dof: int, expected: float, row_variance: float) -> float:
    """The misfit m [ln R] (an extra scatter per row beyond the expected repeatability) the
    repeatability check finds with probability :data:`DETECTION_POWER`. The check fails
    where Q(line) = Σ rᵢ²/(vᵢ + line²) exceeds χ²_dof's (1 + level)/2 point; with rows of
    variance v + s², s² = expected² + m², Q(line) ≈ (v + s²)/(v + line²) · χ²_dof, so the
    power reaches :data:`DETECTION_POWER` where (v + s²)/(v + line²) = χ²_dof,0.975 /
    χ²_dof,0.2 (``row_variance``: v, the rows' typical variance besides σ_rep;
    tests/test_model_check.py checks it by simulation)."""
    line = POOR_MULTIPLE * expected
    tail = (1.0 - INTERVAL_LEVEL) / 2
    ratio = chi2_distribution.isf(tail, dof) / chi2_distribution.ppf(1.0 - DETECTION_POWER, dof)
    total = (row_variance + line**2) * ratio - row_variance
    return math.sqrt(max(total - expected**2, 0.0))


@dataclass(frozen=True)
class FitQuality:
    """How well a fit describes its rows: its χ², the checks against the data (the learned
    repeatability against the expected one, or χ² against the rows' σ; the residuals'
    trends), what they could detect and a statement in words.

    Attributes:
        chi2: the weighted sum of squared residuals at the optimum.
        dof: degrees of freedom, rows − free parameters (− 1 where the repeatability is
            learned: σ_rep is one more parameter fitted to the rows).
        learned_repeatability: σ_rep [ln R] when it was set by the Paule–Mandel condition
            (:mod:`brdf_infer.fit.lsq`: χ² = rows − free parameters), else None.
        repeatability: its check against ``expected_repeatability``
            (:func:`repeatability_check`; None: not judged).
        expected_repeatability: the scene's ``[errors] expected_repeatability`` [ln R].
        trend_p_values: :func:`residual_trends` of the fit (empty: not judged).
        trend_statistic: the joint trend test's F statistic (NaN: not judged).
        trend_detectable: :func:`detectable_trends` of the fit [ln R] (empty: not judged).
        row_variance: the rows' typical variance besides σ_rep (the median of their value's
            and angle terms') [ln R²], for what the repeatability check could detect
            (:func:`detectable_scatter`; None: not stated).
    """

    chi2: float
    dof: int
    learned_repeatability: float | None = None
    repeatability: RepeatabilityCheck | None = None
    expected_repeatability: float | None = None
    trend_p_values: Mapping[str, float] = field(default_factory=dict)
    trend_statistic: float = math.nan
    trend_detectable: Mapping[str, float] = field(default_factory=dict)
    row_variance: float | None = None

    @property
    def chi2_dof(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else math.nan

    @property
    def p_value(self) -> float:
        """P(χ² ≥ the fit's χ²) for a right model with right σ."""
        return float(chi2_distribution.sf(self.chi2, self.dof)) if self.dof > 0 else math.nan

    @property
    def sigma_factor(self) -> float:
        """√(χ²/dof): what the 1σ is multiplied by when scaled (1 where undefined, and where the
        repeatability is learned: its χ² is set by construction and says nothing)."""
        if self.learned_repeatability is not None or self.dof <= 0 or self.chi2 <= 0:
            return 1.0
        return math.sqrt(self.chi2_dof)

    @property
    def poor_line(self) -> float | None:
        """:data:`POOR_MULTIPLE` × the expected repeatability [ln R] (None: not judged)."""
        if self.expected_repeatability is None:
            return None
        return POOR_MULTIPLE * self.expected_repeatability

    @property
    def reasons(self) -> list[str]:
        """What makes the fit poor: ``"repeatability"``, ``"chi2"``, ``"residual trend"``
        (empty: no misfit detected)."""
        if self.dof <= 0:
            return []
        reasons = []
        if self.learned_repeatability is not None:
            line, check = self.poor_line, self.repeatability
            if check is not None and line is not None and check.low > line:
                reasons.append("repeatability")
        elif self.chi2_dof > POOR_CHI2_DOF and self.p_value < POOR_P_VALUE:
            reasons.append("chi2")
        if self.trend_p_values.get("joint", math.nan) < TREND_P_VALUE:
            reasons.append("residual trend")
        return reasons

    @property
    def poor(self) -> bool:
        return bool(self.reasons)

    @property
    def verdict(self) -> str:
        """``no misfit detected``, ``poor`` or ``undefined`` (no degrees of freedom)."""
        if self.dof <= 0:
            return "undefined"
        return "poor" if self.poor else NO_MISFIT

    def _repeatability_text(self) -> str:
        learned = f"the learned repeatability {self.learned_repeatability:.3g} (in ln R"
        check, line = self.repeatability, self.poor_line
        if check is None or line is None:
            return learned + ")"
        interval = f"{100 * INTERVAL_LEVEL:.0f} % {check.low:.2g}–{check.high:.2g}"
        expected = (
            f"{POOR_MULTIPLE:g} × the expected repeatability {self.expected_repeatability:.3g}"
        )
        if "repeatability" in self.reasons:
            return (
                f"{learned}, {interval}) lies wholly above {expected}, more than the scene's "
                "error model gives its data: the model leaves scatter the instrument does not "
                "make"
            )
        return f"{learned}, {interval}) is not wholly above {expected}"

    def _trend_text(self) -> str:
        joint = self.trend_p_values.get("joint", math.nan)
        if math.isnan(joint):
            return ""
        if "residual trend" not in self.reasons:
            return f"the residuals show no trend in θs, θi or series (joint p = {joint:.2g})"
        worst = min(
            (name for name in TREND_GROUPS if name in self.trend_p_values),
            key=lambda name: self.trend_p_values[name],
        )
        return (
            f"the residuals trend with {worst.replace('theta_', 'θ')} (p = "
            f"{self.trend_p_values[worst]:.2g}; joint p = {joint:.2g} < {TREND_P_VALUE:g}): "
            "the model's shape does not follow the data"
        )

    @property
    def detectable(self) -> str:
        """What the fit's checks could detect, in words (80 % power at p < 0.001)."""
        parts = []
        if self.learned_repeatability is not None and self.poor_line is not None:
            parts.append(self._scatter_words())
        elif self.learned_repeatability is None:
            parts.append(
                f"scatter beyond √{POOR_CHI2_DOF:g} × the rows' σ (χ²/dof > {POOR_CHI2_DOF:g})"
            )
        trends = detectable_words(self.trend_detectable)
        if trends:
            parts.append(trends)
        return ", ".join(parts)

    @property
    def statement(self) -> str:
        """The quality in one line, starting with ``poor:``, ``no misfit detected`` or
        ``undefined:``; a fit that learns its repeatability has χ² = rows − parameters by
        construction, so no χ² is stated for it."""
        if self.dof <= 0:
            return "undefined: no degrees of freedom left (as many parameters as rows)"
        findings = []
        if self.learned_repeatability is not None:
            findings.append(self._repeatability_text())
        else:
            p = f"p = {self.p_value:.2g}" if self.p_value > 0 else "p < 1e-300"
            measured = f"χ²/dof = {self.chi2_dof:.3g} for {self.dof} dof ({p})"
            if "chi2" in self.reasons:
                measured += (
                    ": the model does not describe the data within their σ; the unscaled 1σ "
                    f"understates the uncertainty by a factor {self.sigma_factor:.3g}, and even "
                    "the scaled one belongs to a model the data reject"
                )
            findings.append(measured)
        trend = self._trend_text()
        if trend:
            findings.append(trend)
        could = self.detectable
        head = self.verdict if not could or self.poor else f"{NO_MISFIT} (it would see {could})"
        return f"{head}: " + "; ".join(findings)

    def _scatter_words(self) -> str:
        """What the repeatability check could detect, in words (:func:`detectable_scatter`;
        without the rows' variance the line it judges by)."""
        if self.row_variance is None:
            line = self.poor_line
            return f"scatter whose 95 % interval clears {line:.2g} in ln R"
        misfit = detectable_scatter(self.dof, self.expected_repeatability, self.row_variance)
        return f"a misfit adding {100 * math.expm1(misfit):.2g} % scatter per row"

    def model_checks(self) -> list[dict[str, Any]]:
        """The fit's checks as entries of a run's ``model_check`` record
        (:mod:`brdf_infer.posterior`): ``fit_repeatability`` or ``fit_chi2``, and
        ``fit_residual_trend``, each with its statistic, p-value, verdict, words and what it
        could detect. Empty without degrees of freedom."""
        if self.dof <= 0:
            return []
        entries = []
        check = self.repeatability
        if self.learned_repeatability is not None and check is not None and self.poor_line:
            entries.append(
                _entry(
                    "fit_repeatability",
                    check.low,
                    check.p_value,
                    "repeatability" not in self.reasons,
                    self._repeatability_text(),
                    self._scatter_words(),
                )
            )
        elif self.learned_repeatability is None:
            entries.append(
                _entry(
                    "fit_chi2",
                    self.chi2_dof,
                    self.p_value,
                    "chi2" not in self.reasons,
                    f"χ²/dof = {self.chi2_dof:.3g} for {self.dof} dof (p = {self.p_value:.2g})",
                    f"scatter beyond √{POOR_CHI2_DOF:g} × the rows' σ",
                )
            )
        joint = self.trend_p_values.get("joint", math.nan)
        if not math.isnan(joint):
            entries.append(
                _entry(
                    "fit_residual_trend",
                    self.trend_statistic,
                    joint,
                    "residual trend" not in self.reasons,
                    self._trend_text(),
                    detectable_words(self.trend_detectable) or "nothing: no degrees of freedom",
                )
            )
        return entries

    def as_json(self) -> dict[str, Any]:
        """The keys a fit's JSON carries: ``chi2_dof``, ``dof``, ``chi2_p_value``,
        ``poor_fit``, ``verdict``, ``poor_reasons``, ``fit_quality`` (the statement),
        ``expected_repeatability``, ``repeatability_interval`` ([low, high] or None),
        ``repeatability_poor_above`` (the line), ``residual_trend_p_values``,
        ``residual_trend_detectable`` (ln R) and ``model_checks``."""
        check = self.repeatability
        return {
            "chi2_dof": self.chi2_dof,
            "dof": self.dof,
            "chi2_p_value": self.p_value,
            "poor_fit": self.poor,
            "verdict": self.verdict,
            "poor_reasons": self.reasons,
            "fit_quality": self.statement,
            "expected_repeatability": self.expected_repeatability,
            "repeatability_interval": None if check is None else [check.low, check.high],
            "repeatability_poor_above": self.poor_line,
            "residual_trend_p_values": dict(self.trend_p_values),
            "residual_trend_detectable": dict(self.trend_detectable),
            "model_checks": self.model_checks(),
        }


NO_MISFIT = "no misfit detected"


def _entry(name, statistic, p, ok, words, detectable) -> dict[str, Any]:
    """One entry of a run's ``model_check`` record (:mod:`brdf_infer.posterior`)."""
    return {
        "name": name,
        "statistic": None if statistic is None or not math.isfinite(statistic) else statistic,
        "p": None if p is None or not math.isfinite(p) else p,
        "ok": bool(ok),
        "words": words,
        "detectable": detectable,
    }


def scaled_sigma(sigma: dict[str, float | None], factor: float) -> dict[str, float | None]:
    """Every 1σ multiplied by ``factor`` (√(χ²/dof): the covariance scaled by χ²/dof); None
    (a flat profile, no 1σ) stays None."""
    return {name: None if value is None else value * factor for name, value in sigma.items()}
