"""Least squares of any model family with optimistix: multi-start, batched, with covariance.

The residuals are the ln R residuals of :func:`brdf_infer.predict.observations.log_reflectance` (the
family, the instrument, Eq. 6), each divided by the row's σ under the scene's error model
(:mod:`brdf_infer.model.error_model`) *without its random effects*: least squares treats the rows as
independent, so

    σ_i² = σ_value,i² + σ_rep² + (g_rot,i σ_rot)² + (g_cam,i σ_cam)²,

the value's own noise, the per-row repeatability and the angle errors propagated through
ln R at the current parameters. The sample and calibration effects, which correlate rows,
are left out; where the repeatability is learned, σ_rep is instead set so that the reduced χ²
is 1 (the Paule–Mandel condition), which folds every unmodelled scatter into it. The angle
terms and σ_rep are updated after each solve until they settle (iteratively reweighted least
squares). The ``spread`` error model keeps its fixed σ_i. Every family is weighted alike, so
that their χ² and learned repeatabilities compare.

The solver works on the free internal coordinates of the family (:mod:`brdf_infer.fit._space`:
Eq. (7)'s scaled internal coordinates with the scene's fixed parameters and bounds, or another
family's own), bounded ones mapped through smooth maps of the real line. The covariance is
the Gauss–Newton (JᵀJ)⁻¹ in the internal coordinates, not scaled by the reduced χ² unless
asked, carried to the physical parameters by the delta method.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from brdf_infer._internal.precision import ensure_float64
from brdf_infer._internal.stored_programs import StoredFunction, register_tree_types
from brdf_infer.errors import BadInputError
from brdf_infer.fit._reweighting import REWEIGHT_TOLERANCE as REWEIGHT_TOLERANCE
from brdf_infer.fit._reweighting import Reweighting
from brdf_infer.fit._reweighting import paule_mandel as paule_mandel
from brdf_infer.fit._space import FitSpace, FreeTransform, physical_of
from brdf_infer.fit._space import fit_space as fit_space
from brdf_infer.fit._space import internal_bounds as internal_bounds
from brdf_infer.fit._space import start_points as start_points
from brdf_infer.fit.quality import (
    LowRankNoise,
    RepeatabilityCheck,
    detectable_trends,
    repeatability_check,
    trend_regressors,
    trend_repeatability,
    trend_tests,
)
from brdf_infer.model import FAMILY_NAMES, ModelFamily, family
from brdf_infer.model.error_model import noise_layout
from brdf_infer.model.params import HemisphereConstants, Params
from brdf_infer.predict.observations import Observations, build_observation_model, log_reflectance
from brdf_infer.scene import Scene
from brdf_infer.scene.settings import LSQ_STARTS
from brdf_infer.tables.measurements import Measurements

# the named tuples of the solver's arguments, which its stored program names
register_tree_types((FreeTransform, Observations, HemisphereConstants))

SOLVERS = {
    "lm": optx.LevenbergMarquardt,
    "gauss-newton": optx.GaussNewton,
    "dogleg": optx.Dogleg,
}
CONVERGED_COST_TOLERANCE = 1e-6  # relative (χ² units, at least 1e-6 absolute)
REWEIGHT_ITERATIONS = 12  # at most, of the σ update (angle terms, Paule–Mandel σ_rep)
ILL_CONDITIONED = 1e8  # condition number of J in internal coordinates
# optimistix outcomes reported per start (anything else is reported as "other")
STATUS_NAMES: tuple[str, ...] = (
    "successful",
    "nonlinear_max_steps_reached",
    "nonlinear_divergence",
    "singular",
    "breakdown",
    "stagnation",
    "max_steps_reached",
    "nonfinite_input",
)


@dataclass(frozen=True)
class LsqResult:
    """Outcome of :func:`fit_lsq`; every number in the family's units unless named otherwise.

    Attributes:
        family: the family fitted.
        physical: best-fit physical parameters, by name, in the family's order.
        cost: χ² = Σ ((ln R_pred − ln R_obs)/σ)² at the optimum.
        reduced_chi2: χ² / (n_points − n_free).
        sigma: 1σ per parameter (0 for fixed ones), linearised: for Eq. (7)'s a2 and a3 it is
            only meaningful when α is well determined, since a2 = b2·90^−(1+α) (see
            ``sigma_internal``); None for a parameter whose profile is flat (:func:`flat_profile`):
            the curvature there is no uncertainty.
        internal: the optimum in internal coordinates (:mod:`brdf_infer.fit._space`).
        sigma_internal: 1σ in internal coordinates, where the linearisation holds better.
        correlation: correlation matrix of the physical parameters (identity rows for fixed
            parameters).
        condition_number: of the Jacobian in the internal coordinates.
        covariance_scaled: whether the covariance was multiplied by the reduced χ².
        n_points: number of residuals.
        free: names of the fitted parameters.
        starts: number of starts.
        starts_converged: starts whose cost is within tolerance of the best.
        start_costs: χ² reached by each start.
        start_status: optimistix status of each start.
        solver: solver name.
        seconds: run time of the batched solve (compilation excluded).
        compile_seconds: compilation time.
        row_sigma: the σ_i that weighted each row at the end [ln R].
        repeatability: σ_rep used (estimated by Paule–Mandel when learned) [ln R].
        repeatability_check: where it is learned, its Q-profile interval and its p-value
            against twice the scene's expected repeatability
            (:func:`brdf_infer.fit.quality.repeatability_check`); else None.
        residual_trend_p_values: F-test p-values of the residuals' trends in θs, θi and series
            (:func:`brdf_infer.fit.quality.residual_trends`; empty without degrees of freedom).
        residual_trend_statistic: the joint trend test's F statistic (NaN: not judged).
        residual_trend_detectable: the smallest trend or offset of each group that test finds
            with 80 % power [ln R] (:func:`brdf_infer.fit.quality.detectable_trends`).
        reweightings: solves of the reweighting loop.
        warnings: identifiability and convergence warnings, in words.
    """

    family: str
    physical: dict[str, float]
    cost: float
    reduced_chi2: float
    sigma: dict[str, float]
    internal: dict[str, float]
    sigma_internal: dict[str, float]
    correlation: np.ndarray
    condition_number: float
    covariance_scaled: bool
    n_points: int
    free: tuple[str, ...]
    starts: int
    starts_converged: int
    start_costs: np.ndarray
    start_status: list[str]
    solver: str
    seconds: float
    compile_seconds: float
    row_sigma: np.ndarray
    repeatability: float
    repeatability_check: RepeatabilityCheck | None
    residual_trend_p_values: dict[str, float]
    residual_trend_statistic: float
    residual_trend_detectable: dict[str, float]
    reweightings: int
    warnings: list[str] = field(default_factory=list)

    @property
    def params(self) -> Params:
        """The optimum as Eq. (7)'s six parameters (its family only).

        Raises:
            ValueError: another family's fit.
        """
        try:
            return Params(**self.physical)
        except TypeError:
            raise ValueError(f"{self.family} has no Eq. (7) parameters") from None


def fit_residuals(
    member: ModelFamily,
    z_free: jnp.ndarray,
    data: Observations,
    transform: FreeTransform,
    free_index: tuple[int, ...],
) -> jnp.ndarray:
    """(ln R_pred − ln R_obs)/σ of every row at the free internal coordinates ``z_free``."""
    physical = physical_of(member, transform.free_to_full(z_free, free_index))
    return (log_reflectance(member, physical, data) - data.log_reflectance) / data.sigma


@functools.cache
def _batched_solver(
    solver: str, rtol: float, atol: float, max_steps: int, free_index, name: str, fold: bool
):
    """Compiled-once solver of the family ``name``: (u0 batch, data, transform, constants) →
    (z_free, cost, status); Eq. (10)'s constants are an argument, not part of the program,
    which a warm run loads without tracing (:mod:`brdf_infer._internal.stored_programs`)."""
    method = SOLVERS[solver](rtol=rtol, atol=atol)

    def solve_one(u0, data, transform, constants):
        member = family(name, fold, constants)

        def residuals(u, _args):
            return fit_residuals(member, transform.to_free(u), data, transform, free_index)

        solution = optx.least_squares(residuals, method, u0, max_steps=max_steps, throw=False)
        cost = jnp.sum(residuals(solution.value, None) ** 2)
        matches = [solution.result == getattr(optx.RESULTS, name) for name in STATUS_NAMES]
        status = jnp.where(jnp.any(jnp.stack(matches)), jnp.argmax(jnp.stack(matches)), -1)
        return transform.to_free(solution.value), cost, status

    identity = ("least squares", solver, rtol, atol, max_steps, free_index, name, fold)
    return StoredFunction(jax.vmap(solve_one, in_axes=(0, None, None, None)), identity)


def fit_lsq(
    scene: Scene,
    measurements: Measurements,
    member: ModelFamily | None = None,
    *,
    starts: int = LSQ_STARTS,
    solver: str = "lm",
    seed: int = 0,
    init: Params | None = None,
    scale_covariance: bool = False,
    rtol: float = 1e-10,
    atol: float = 1e-10,
    max_steps: int = 1000,
) -> LsqResult:
    """Multi-start least-squares fit of a family's free parameters.

    Args:
        scene: error model, priors (start ranges, bounds, fixed values of Eq. 7), model.
        measurements: the rows to fit (every sample individually).
        member: the family (default: the scene's, with its folding and constants).
        starts: number of starting points, solved together in one compiled, vmapped call.
        solver: ``lm`` (Levenberg–Marquardt), ``gauss-newton`` or ``dogleg``.
        seed: seed of the starting points.
        init: Eq. (7)'s family only: if given, the first start (the others stay random).
        scale_covariance: multiply the covariance by the reduced χ² (not done when χ² ≈ 0).
        rtol, atol: solver tolerances.
        max_steps: solver step limit per start.

    Raises:
        BadInputError: unknown solver, fewer than one start, or fewer points than free
            parameters.
        ValueError: a family outside the registry, or ``init`` for another family than
            Eq. (7)'s.
    """
    ensure_float64()
    if member is None:
        member = family(scene.model.family, scene.model.fold, scene.model.constants)
    elif member.name not in FAMILY_NAMES:  # the solver rebuilds it from the registry
        raise ValueError(f"{member.name!r} is not a registered model family")
    space = fit_space(scene, member)
    model = _checked_model(scene, measurements, space, solver, starts)
    transform = space.transform
    z0 = start_points(scene, space, starts, seed, init)
    u0 = jnp.asarray(np.stack([transform.from_free(z) for z in z0]))
    solve = _batched_solver(
        solver, rtol, atol, max_steps, space.free_index, member.name, member.fold
    )
    layout = noise_layout(scene.errors, measurements)
    reweight = Reweighting(scene, model, member, len(space.free), layout)
    model = model.with_sigma(reweight.sigma)
    solved = _solve_reweighted(solve, u0, model, space, reweight)
    return _lsq_result(
        scene, measurements, solved, space, reweight, starts, solver, scale_covariance
    )


def _checked_model(scene: Scene, measurements: Measurements, space: FitSpace, solver, starts):
    """The observation model of the rows, once the solver, the starts and the number of points
    are checked (:func:`fit_lsq` Raises)."""
    if solver not in SOLVERS:
        raise BadInputError(
            f"unknown solver {solver!r} (known: {', '.join(SOLVERS)})", field="solver"
        )
    if starts < 1:
        raise BadInputError(f"need at least one start, got {starts}", field="starts")
    model = build_observation_model(scene, measurements)
    if model.n_points < len(space.free):
        fix = " (fix some in the scene's [priors])" if space.member.paper_parameters else ""
        raise BadInputError(
            f"{model.n_points} measurements cannot constrain {len(space.free)} free "
            f"parameters{fix}",
            file=measurements.path,
        )
    return model


class _Solved(NamedTuple):
    """The last solve of :func:`_solve_reweighted` and the model (row weights) it used."""

    model: Any
    z_free: Any
    costs: Any
    status: Any
    settled: bool
    seconds: float
    compile_seconds: float


def _solve_reweighted(solve, u0, model, space: FitSpace, reweight: Reweighting) -> _Solved:
    """Compile the batched solver once and solve from every start, reweighting the rows and
    solving again until the weights settle (at most ``REWEIGHT_ITERATIONS`` solves)."""
    transform, constants = space.transform, space.member.constants
    arguments = (model.data, transform, constants)
    clock = time.perf_counter()
    compiled = solve.compiled(u0, *arguments)
    compile_seconds = time.perf_counter() - clock
    clock = time.perf_counter()
    settled = False
    while not settled:
        z_free, costs, status = jax.block_until_ready(compiled(u0, *arguments))
        best_index = int(np.argmin(np.where(np.isfinite(costs), costs, np.inf)))
        best = transform.free_to_full(z_free[best_index], space.free_index)
        settled = not reweight.update(physical_of(space.member, best))
        if not settled and reweight.solves >= REWEIGHT_ITERATIONS:
            break
        if not settled:
            model = model.with_sigma(reweight.sigma)
            arguments = (model.data, transform, constants)
            u0 = u0.at[0].set(jnp.asarray(transform.from_free(np.asarray(z_free[best_index]))))
    seconds = time.perf_counter() - clock
    return _Solved(model, z_free, costs, status, settled, seconds, compile_seconds)


def _lsq_result(
    scene: Scene,
    measurements: Measurements,
    solved: _Solved,
    space: FitSpace,
    reweight: Reweighting,
    starts: int,
    solver: str,
    scale_covariance: bool,
) -> LsqResult:
    """The best start of the last solve, its covariance and the fit's warnings."""
    model, z_free, status, settled = solved.model, solved.z_free, solved.status, solved.settled
    member, transform, free_index = space.member, space.transform, space.free_index
    costs = np.where(np.isfinite(solved.costs), np.asarray(solved.costs), np.inf)
    best_index = int(np.argmin(costs))
    best_cost = float(costs[best_index])
    tolerance = CONVERGED_COST_TOLERANCE * max(1.0, best_cost)
    converged = int(np.sum(np.abs(costs - best_cost) <= tolerance))
    z_best = np.asarray(z_free[best_index])
    z_full = transform.free_to_full(jnp.asarray(z_best), free_index)
    physical = {n: float(v) for n, v in physical_of(member, z_full).items()}

    dof = model.n_points - len(space.free)
    reduced = best_cost / dof if dof > 0 else float("nan")

    def residuals_free(z):
        return fit_residuals(member, z, model.data, transform, free_index)

    def free_to_physical(z):
        values = physical_of(member, transform.free_to_full(z, free_index))
        return jnp.stack([jnp.asarray(values[n], float) for n in member.parameters])

    covariance_free, condition, warnings, absorbed = _internal_covariance(
        residuals_free, z_best, reduced if scale_covariance else None
    )
    jacobian_physical = np.asarray(jax.jacfwd(free_to_physical)(jnp.asarray(z_best)))
    covariance = jacobian_physical @ covariance_free @ jacobian_physical.T
    sigma_internal = np.zeros(len(space.names))
    sigma_internal[list(free_index)] = np.sqrt(np.clip(np.diag(covariance_free), 0.0, None))
    sigma = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    sigma_of = dict(zip(member.parameters, map(float, sigma), strict=True))
    warnings += _identifiability_warnings(
        measurements, physical, sigma_of, condition, space, z_best
    )
    for name in flat_profile(scene, space, sigma_of):
        sigma_of[name] = None
    warnings += _solver_warnings(settled, reweight, converged, starts, best_cost)
    row_sigma = np.asarray(model.data.sigma)
    residuals = np.asarray(residuals_free(jnp.asarray(z_best))) * row_sigma  # [ln R]
    return LsqResult(
        family=member.name,
        physical=physical,
        cost=best_cost,
        reduced_chi2=reduced,
        sigma=sigma_of,
        internal=dict(zip(space.names, map(float, z_full), strict=True)),
        sigma_internal=dict(zip(space.names, map(float, sigma_internal), strict=True)),
        correlation=_correlation(covariance, sigma),
        condition_number=condition,
        covariance_scaled=bool(scale_covariance and "zero residual" not in " ".join(warnings)),
        n_points=model.n_points,
        free=space.free,
        starts=starts,
        starts_converged=converged,
        start_costs=costs,
        start_status=[STATUS_NAMES[s] if s >= 0 else "other" for s in np.asarray(status)],
        solver=solver,
        seconds=solved.seconds,
        compile_seconds=solved.compile_seconds,
        row_sigma=row_sigma,
        repeatability=reweight.repeatability,
        repeatability_check=_repeatability_check(scene, reweight, residuals),
        **_residual_trends(scene, measurements, residuals, row_sigma, absorbed, reweight),
        reweightings=reweight.solves,
        warnings=warnings,
    )


def _solver_warnings(
    settled: bool, reweight: Reweighting, converged: int, starts: int, best_cost: float
) -> list[str]:
    """Row weights that had not settled, and too few starts reaching the best cost."""
    warnings = []
    if not settled:
        warnings.append(
            f"the row weights had not settled after {reweight.solves} reweighted solves"
        )
    if converged < 0.8 * starts:
        warnings.append(
            f"only {converged} of {starts} starts reached the best cost {best_cost:.6g}"
        )
    return warnings


def _repeatability_check(scene, reweight: Reweighting, residuals) -> RepeatabilityCheck | None:
    """A learned repeatability's interval and p-value against the scene's expected one (None:
    not learned); ``residuals``: the fit's, in ln R."""
    if not reweight.learned:
        return None
    variances = reweight.value_variance + reweight.angle_variance
    expected = scene.errors.expected_repeatability
    return repeatability_check(residuals, variances, reweight.dof, expected)


def _residual_trends(
    scene, measurements, residuals, sigma, absorbed, reweight: Reweighting
) -> dict[str, Any]:
    """The residual-trend fields of :class:`LsqResult`: the tests' p-values, the joint F and
    what it could detect (:func:`brdf_infer.fit.quality.trend_tests`,
    :func:`~brdf_infer.fit.quality.detectable_trends`), with
    the rows whitened by the error model's covariance as least squares knows it: each row's
    σ² of the last solve, with its rotation term shared by the rows of one rotation setting,
    and the scene's calibration factors (the sample effect, whose scale the scene does not
    state, left out); a learned repeatability is learned again for the tests, beside the
    trend columns and with the calibration factors in the covariance
    (:func:`~brdf_infer.fit.quality.trend_repeatability`: the fit's own σ_rep, learned with
    the rows independent, holds the calibration scatter and the misfit too, and the F-test's
    free scale would shrink the stated calibration with it); ``absorbed``: a basis of what the
    fitted parameters absorb, in σ-weighted residuals."""
    if reweight.dof <= 0:
        return {
            "residual_trend_p_values": {},
            "residual_trend_statistic": float("nan"),
            "residual_trend_detectable": {},
        }
    layout = reweight.layout
    rotation = reweight.rotation_slope * np.asarray(layout.rotation_deg, float)
    calibration = np.asarray(layout.calibration_sd, float)
    rotation_alone = np.asarray(layout.rotation_alone, float)
    noise = LowRankNoise(  # no rows × rows object: the parts of D + W Wᵀ
        diagonal=sigma**2
        - rotation**2 * (1.0 - rotation_alone)
        + calibration**2 * np.asarray(layout.calibration_alone, float),
        factor=np.column_stack(
            [
                rotation[:, None] * np.asarray(layout.rotation_members, float),
                calibration[:, None] * np.asarray(layout.calibration_members, float),
            ]
        ),
    )
    regressors = trend_regressors(
        measurements.theta_i_deg, measurements.theta_s_deg, np.asarray(measurements.series)
    )
    base = sigma[:, None] * absorbed
    if reweight.learned:  # the repeatability re-learned beside the trends and calibration
        without = noise._replace(diagonal=noise.diagonal - reweight.repeatability**2)
        own = trend_repeatability(residuals, without, base, regressors)
        noise = without._replace(diagonal=without.diagonal + own**2)
    tests = trend_tests(residuals, noise, base, regressors)
    return {
        "residual_trend_p_values": {name: p for name, (_, p) in tests.items()},
        "residual_trend_statistic": tests["joint"][0],
        "residual_trend_detectable": detectable_trends(noise, base, regressors),
    }


def _internal_covariance(residuals_free, z_best, reduced_chi2):
    """(JᵀJ)⁻¹ in the free internal coordinates (pseudo-inverse), cond(J), the warnings and
    an orthonormal basis of J's columns, what of the weighted residuals the fitted parameters
    absorb."""
    warnings = []
    jacobian = np.asarray(jax.jacfwd(residuals_free)(jnp.asarray(z_best)))
    singular_values = np.linalg.svd(jacobian, compute_uv=False)
    condition = (
        float(singular_values[0] / singular_values[-1]) if singular_values[-1] > 0 else np.inf
    )
    u, s, vt = np.linalg.svd(jacobian, full_matrices=False)
    keep = s > s[0] * 1e-14
    covariance_free = (vt[keep].T / s[keep] ** 2) @ vt[keep]
    if not keep.all():
        warnings.append("the Jacobian is singular: some parameter combinations are not determined")
    if reduced_chi2 is not None:
        if reduced_chi2 > 1e-20:
            covariance_free = covariance_free * reduced_chi2
        else:
            warnings.append("zero residual: covariance left unscaled by the reduced chi2")
    return covariance_free, condition, warnings, u[:, keep]


def _correlation(covariance: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    positive = sigma > 0
    outer = np.outer(np.where(positive, sigma, 1.0), np.where(positive, sigma, 1.0))
    correlation = np.where(np.outer(positive, positive), covariance / outer, 0.0)
    np.fill_diagonal(correlation, 1.0)
    return np.clip(correlation, -1.0, 1.0)


def flat_profile(scene: Scene, space: FitSpace, sigma: dict[str, float]) -> list[str]:
    """Eq. (7)'s bounded parameters (α, θs0) whose linearised 1σ exceeds their prior's sd (a
    uniform prior: its range / √12): the data constrain them less than the prior does, the
    least-squares profile is flat there, and the curvature's 1σ describes no uncertainty (the
    posterior says what data and prior leave of it)."""
    if not space.member.paper_parameters:
        return []
    flat = []
    for name in ("alpha", "theta_s0"):
        prior = scene.priors[name]
        if name not in space.free or prior.kind == "normal":
            continue
        spread = prior.scale if prior.kind != "uniform" else (prior.upper - prior.lower) / 12**0.5
        if sigma[name] > spread:
            flat.append(name)
    return flat


def _identifiability_warnings(measurements, physical, sigma, condition, space, z_best):
    warnings = []
    if condition > ILL_CONDITIONED:
        warnings.append(
            f"ill-conditioned Jacobian (condition number {condition:.2g}): the data do not "
            "identify every parameter combination; see the correlation matrix"
        )
    lowest = float(np.min(measurements.theta_s_deg))
    if space.member.paper_parameters and "theta_s0" in space.free and lowest > physical["theta_s0"]:
        warnings.append(
            f"theta_s0 is not identified directly: no measurement lies below theta_s0 = "
            f"{physical['theta_s0']:.3g} deg (lowest theta_s = {lowest:.3g} "
            f"deg); it is constrained only through the curve's shape above it"
        )
    transform = space.transform
    for position, name in enumerate(space.names[k] for k in space.free_index):
        if not transform.bounded[position]:
            continue
        value = z_best[position]
        lower, upper = float(transform.lower[position]), float(transform.upper[position])
        if min(value - lower, upper - value) < 1e-3 * (upper - lower):
            label = space.free[position] if space.member.paper_parameters else name
            warnings.append(f"{label} ended at a bound of its range: the optimum may lie beyond it")
    return warnings
