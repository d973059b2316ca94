"""Laplace's approximation corrected by Pareto-smoothed importance sampling, for large tables.

With thousands of rows the posterior of the handful of parameters is close to normal on the
unconstrained space, and NUTS pays for its trajectories with one gradient over every row per
leapfrog step (about 60 ms at 6 × 10⁴ rows on 2 cores). This sampler instead

1. finds the mode of the potential U(z) = −log p(z | y) with BFGS from :data:`STARTS`
   dispersed points, and refuses the approximation when a search ends as low as the best
   but far from it (a second mode: what R-hat would see between NUTS chains);
2. takes the Hessian H of U at the mode by central differences of the gradient, then along
   its eigenvectors with a step of one standard deviation (:meth:`LaplaceProgram.hessian`;
   ``jax.hessian`` would compile for about half a minute);
3. draws S = chains × draws proposals from a multivariate Student-t q centred at the mode
   with scale H⁻¹ and :data:`DEGREES_OF_FREEDOM` (its tails heavier than a normal target's, so
   the importance weights have a finite variance), after adapting q to weighted trial draws
   while their Pareto k̂ is high (:meth:`LaplaceProgram.adapted_sample`), each U(z)
   evaluated in compiled blocks;
4. weights them by p/q, smooths the weights' tail with PSIS (Vehtari et al. 2024, *Pareto
   smoothed importance sampling*, JMLR 25(72)) and refuses the result when the Pareto shape k̂
   exceeds :func:`pareto_k_limit` (the paper's threshold for a reliable estimate, 0.7 from
   about 2200 draws; :func:`laplace_draws` then says why and the caller samples with NUTS);
5. resamples the proposals by their smoothed weights (systematic resampling), so that every
   reader of the run sees equally weighted draws as from any sampler; the draws are dealt to
   ``chains`` exchangeable chains, between which R-hat is not a diagnostic (it is recorded,
   not checked: k̂ and the effective sample size below are the checks).

The effective sample size of a weighted set is Kish's 1/Σw̃² (w̃ normalised); the diagnostics
report it in place of ArviZ's ESS of the resampled chains, which would count repeated draws.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer._internal import arviz as az
from brdf_infer._internal.stored_programs import StoredFunction
from brdf_infer.posterior._compile_clock import compile_clock
from brdf_infer.posterior._model import PosteriorModel, model_identity
from brdf_infer.posterior._nuts import same_structure
from brdf_infer.posterior._potential import FlatPotential
from brdf_infer.posterior._samplers import Draws, Refused
from brdf_infer.verdict import PARETO_K_LIMIT, pareto_k_limit

STARTS = 4  # BFGS searches from dispersed points
SEARCH_TOLERANCE, SEARCH_STEPS = 1e-10, 2000  # of each search
DEGREES_OF_FREEDOM = 7.0  # of the Student-t proposal
ADAPT_K = 0.5  # Pareto k below which the proposal is kept as it is ...
ADAPT_ESS = 0.25  # ... if Kish's ESS is at least this fraction of the trial proposals
ADAPT_ROUNDS = 3  # adaptations of the proposal at most
ADAPT_DRAWS = 1000  # trial proposals of one adaptation
BLOCK_CELLS = 2**22  # rows × proposals of one compiled evaluation of U (memory)
STEP = 1e-4  # central-difference step of the Hessian, unconstrained units
SECANT_PASSES = 2  # of the Hessian at one standard deviation (hessian)
# a search's end as low as the mode's (U within RIVAL_POTENTIAL) but RIVAL_DISTANCE standard
# deviations away in H's metric is a second mode the proposal would miss; ends higher up (a
# search that stopped on the slow slope of a noise scale's lower tail) are not
RIVAL_POTENTIAL = 1.0
RIVAL_DISTANCE = 5.0
NEWTON_STEPS = 6  # towards a variant's mode from the run's mean (newton_proposal)
NEWTON_DECREMENT = 1e-4  # gᵀ H⁻¹ g below which the mode is reached (U within 5e-5)


@dataclass(frozen=True)
class LaplaceFit:
    """The mode, the Hessian there and how the searches ended.

    Attributes:
        mode: (d,) the lowest-potential search's end, unconstrained.
        hessian: (d, d) of U at the mode.
        potentials: (STARTS,) U at every search's end.
        distances: (STARTS,) squared H-distance of every search's end from the mode.
        refusal: why the approximation is not used (None: it is).
    """

    mode: np.ndarray
    hessian: np.ndarray
    potentials: np.ndarray
    distances: np.ndarray
    refusal: str | None


@dataclass(frozen=True)
class Proposal:
    """A multivariate Student-t (ν = :data:`DEGREES_OF_FREEDOM`): centre and scale matrix."""

    centre: np.ndarray
    scale: np.ndarray

    def draw(self, count: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """(count, d) draws and their log density."""
        lower = np.linalg.cholesky(self.scale)
        normal = rng.standard_normal((count, self.centre.size))
        radial = np.sqrt(rng.chisquare(DEGREES_OF_FREEDOM, count) / DEGREES_OF_FREEDOM)
        draws = self.centre + (normal @ lower.T) / radial[:, None]
        return draws, _student_t_log_density(draws, self.centre, lower)

    @classmethod
    def weighted(cls, points: np.ndarray, log_weights: np.ndarray) -> Proposal:
        """The proposal with the weighted mean and covariance of ``points`` (its scale
        matrix (ν − 2)/ν times that covariance, so that its covariance is the weighted one)."""
        weights = np.exp(log_weights - np.max(log_weights))
        weights /= weights.sum()
        centre = weights @ points
        offsets = points - centre
        covariance = (weights[:, None] * offsets).T @ offsets
        shrink = (DEGREES_OF_FREEDOM - 2) / DEGREES_OF_FREEDOM
        return cls(centre, shrink * 0.5 * (covariance + covariance.T))


def _student_t_log_density(points, centre, lower) -> np.ndarray:
    """Log density of the multivariate Student-t (ν = :data:`DEGREES_OF_FREEDOM`) with scale
    matrix L Lᵀ at ``points`` (n, d)."""
    from scipy.special import gammaln

    nu, dimension = DEGREES_OF_FREEDOM, centre.size
    whitened = np.linalg.solve(lower, (points - centre).T)
    squared = np.sum(whitened**2, axis=0)
    constant = gammaln((nu + dimension) / 2) - gammaln(nu / 2)
    constant -= 0.5 * dimension * np.log(nu * np.pi) + np.sum(np.log(np.diag(lower)))
    return constant - 0.5 * (nu + dimension) * np.log1p(squared / nu)


def _mapped(function: Callable, identity: tuple) -> Callable:
    """``function(point, data)`` over a leading axis of points, compiled (``lax.map``) and
    stored for warm runs under ``identity``, the values it closes over
    (:class:`~brdf_infer._internal.stored_programs.StoredFunction`)."""
    return StoredFunction(
        lambda points, data: jax.lax.map(lambda point: function(point, data), points), identity
    )


def _positive_definite(matrix: np.ndarray) -> bool:
    return bool(np.all(np.isfinite(matrix)) and np.all(np.linalg.eigvalsh(matrix) > 0))


def kish_ess(log_weights: np.ndarray) -> float:
    """Kish's effective sample size 1/Σw̃² of normalised weights given by their logs."""
    weights = np.exp(log_weights - np.max(log_weights))
    weights /= weights.sum()
    return float(1.0 / np.sum(weights**2))


def systematic_resample(log_weights: np.ndarray, count: int, rng: np.random.Generator):
    """``count`` indices drawn by systematic resampling with the given log weights."""
    weights = np.exp(log_weights - np.max(log_weights))
    cumulative = np.cumsum(weights / weights.sum())
    cumulative[-1] = 1.0
    positions = (rng.uniform() + np.arange(count)) / count
    return np.searchsorted(cumulative, positions)


@dataclass(frozen=True)
class ImportanceSample:
    """Proposals with their potential U and PSIS-smoothed normalised log weights."""

    points: np.ndarray
    potentials: np.ndarray
    log_weights: np.ndarray
    pareto_k: float
    rounds: int  # adaptations of the proposal before the final draws


class LaplaceProgram:
    """The compiled programs of Laplace + PSIS for one model structure, the data an argument
    of each (a variant of the model that differs in data only reuses them; the persistent
    compilation cache keys them by shape, not by the rows' values)."""

    def __init__(self, model: PosteriorModel):
        self.model = model
        flat = self.flat = FlatPotential(model)

        def search(key, data):
            return flat.search(key, data, SEARCH_TOLERANCE, SEARCH_STEPS)

        # one point at a time (lax.map), not vmapped: the same numbers to rounding, but on a
        # CPU (1986 rows, warm cache) the vmapped BFGS loop traced 2.4× and ran 2.7× longer,
        # the vmapped gradient ran 1.5× longer
        identity = (model_identity(model), SEARCH_TOLERANCE, SEARCH_STEPS)
        self._search = _mapped(search, ("laplace search", *identity))
        self._gradients = _mapped(jax.grad(flat.potential), ("laplace gradient", *identity))
        self._potentials = _mapped(flat.potential, ("laplace potential", *identity))
        self._constrain = _mapped(flat.constrain, ("laplace constrain", *identity))
        rows = int(np.shape(model.data.mask)[0])
        self.block = int(np.clip(2 ** int(np.log2(max(1, BLOCK_CELLS // rows))), 8, 256))

    def serves(self, model: PosteriorModel) -> bool:
        """Whether these programs serve ``model`` (the same but for its data)."""
        return same_structure(model, self.model)

    def hessian(self, data, at: np.ndarray) -> np.ndarray:
        """H of U at ``at``: central differences of the gradient, first with the step
        :data:`STEP` along the axes, then :data:`SECANT_PASSES` times along the eigenvectors
        of the last estimate with a step of one standard deviation (eigenvalue^-1/2) each: a
        secant curvature over the posterior's width, which the kinks of Eq. (7) in θs0 (its x'
        clipped at zero) would otherwise make the curvature at one point."""
        directions, steps = np.eye(at.size), np.full(at.size, STEP)
        for _ in range(1 + SECANT_PASSES):
            shifts = np.concatenate([directions * steps, -directions * steps], axis=1).T
            gradients = np.asarray(self._gradients(jnp.asarray(at + shifts), data))
            columns = (gradients[: at.size] - gradients[at.size :]).T / (2 * steps)  # H v_k
            matrix = columns @ directions.T
            matrix = 0.5 * (matrix + matrix.T)
            values, directions = np.linalg.eigh(matrix)
            if not np.all(np.isfinite(values)) or np.any(values <= 0):
                break
            steps = 1.0 / np.sqrt(values)
        return matrix

    def newton_proposal(self, data, start: Proposal) -> Proposal | None:
        """The Student-t at the mode of U reached by Newton steps from ``start``'s centre,
        with scale H⁻¹ there (:meth:`hessian` at each point): a variant's posterior that lies
        away from the run's draws (:func:`importance_refit`) without the mode searches. Each
        step is the best of it and its halvings, evaluated in one compiled block (where H is
        not positive definite, ``start``'s inverse scale takes its place); at most
        :data:`NEWTON_STEPS`, until the Newton decrement gᵀ H⁻¹ g < :data:`NEWTON_DECREMENT`.
        None where the Hessian at the end is not positive definite."""
        point = start.centre
        potential = self.potentials(data, point[None])[0]
        halvings = 0.5 ** np.arange(self.block)
        fallback = np.linalg.inv(start.scale)  # where U is not convex: the start's metric
        for _ in range(NEWTON_STEPS):
            matrix = self.hessian(data, point)
            if not _positive_definite(matrix):
                matrix = fallback
            batch = jnp.asarray(np.repeat(point[None], 2 * point.size, axis=0))
            gradient = np.asarray(self._gradients(batch, data))[0]
            step = np.linalg.solve(matrix, gradient)
            candidates = point - halvings[:, None] * step
            values = self.potentials(data, candidates)
            best = int(np.argmin(values))
            if values[best] >= potential:
                break
            point, potential = candidates[best], values[best]
            if gradient @ step < NEWTON_DECREMENT:
                break
        matrix = self.hessian(data, point)
        return Proposal(point, np.linalg.inv(matrix)) if _positive_definite(matrix) else None

    def fit(self, data, seed: int) -> LaplaceFit:
        """The mode and Hessian of U (module docstring, steps 1–2), or why not to use them."""
        keys = jax.random.split(jax.random.PRNGKey(seed + 2), STARTS)
        ends, potentials, converged = (np.asarray(a) for a in self._search(keys, data))
        finite = np.isfinite(potentials)
        best = int(np.argmin(np.where(finite, potentials, np.inf)))
        mode = ends[best]
        matrix = self.hessian(data, mode)
        offsets = ends - mode
        distances = np.einsum("si,ij,sj->s", offsets, matrix, offsets)
        rival = (potentials - potentials[best] < RIVAL_POTENTIAL) & (distances > RIVAL_DISTANCE**2)
        refusal = None
        if not np.all(finite & converged):
            failed = int(np.sum(~(finite & converged)))
            refusal = f"{failed} of {STARTS} mode searches did not converge"
        elif np.any(rival):
            refusal = (
                f"a mode search ended within {RIVAL_POTENTIAL} of the lowest potential but "
                f"{np.sqrt(distances[rival].max()):.1f} standard deviations away: a second mode"
            )
        elif not np.all(np.isfinite(matrix)) or np.any(np.linalg.eigvalsh(matrix) <= 0):
            refusal = "the Hessian at the mode is not positive definite"
        return LaplaceFit(mode, matrix, potentials, distances, refusal)

    def _blocks(self, points: np.ndarray):
        """``points`` in blocks of :attr:`block` rows (the last padded with the first point),
        each with its number of real rows."""
        for start in range(0, len(points), self.block):
            block = points[start : start + self.block]
            padding = np.repeat(points[:1], self.block - len(block), axis=0)
            yield jnp.asarray(np.concatenate([block, padding])), len(block)

    def potentials(self, data, points: np.ndarray) -> np.ndarray:
        """U at every row of ``points`` through one compiled program; non-finite as +inf."""
        values = [
            np.asarray(self._potentials(block, data))[:real] for block, real in self._blocks(points)
        ]
        potentials = np.concatenate(values)
        return np.where(np.isfinite(potentials), potentials, np.inf)

    def constrained(self, data, points: np.ndarray) -> dict[str, np.ndarray]:
        """Every site of the model at each row of ``points``."""
        parts = []
        for block, real in self._blocks(points):
            sites = self._constrain(block, data)
            parts.append({name: np.asarray(value)[:real] for name, value in sites.items()})
        return {name: np.concatenate([part[name] for part in parts]) for name in parts[0]}

    def weighted(self, data, proposal: Proposal, count: int, rng) -> ImportanceSample:
        """``count`` proposals, their U and PSIS-smoothed normalised log weights."""
        points, proposal_density = proposal.draw(count, rng)
        potentials = self.potentials(data, points)
        smoothed, pareto_k = az.psislw(-potentials - proposal_density)
        return ImportanceSample(points, potentials, np.asarray(smoothed), float(pareto_k), 0)

    def adapted_sample(
        self,
        data,
        proposal: Proposal,
        count: int,
        rng,
        target_ess: float | None = None,
        rescue: Callable[[], Proposal | None] | None = None,
    ) -> ImportanceSample:
        """``count`` proposals from ``proposal``, weighted; while their Pareto k exceeds
        :data:`ADAPT_K` or Kish's ESS is below :data:`ADAPT_ESS` of them (at most
        :data:`ADAPT_ROUNDS` times) the proposal first takes the weighted mean and covariance
        of :data:`ADAPT_DRAWS` trial proposals (adaptive importance sampling: the curvature at
        the mode can misjudge the width where the potential has kinks or a long tail, and a
        variant's posterior can be narrower than the run's it starts from). The best trial's
        q (the lowest k̂ where above :data:`ADAPT_K`, else the highest ESS: a noisy
        adaptation can be worse than its start) draws the final proposals afresh (the trial
        that stopped the adaptation is not among them: keeping it would favour weights that
        looked good). ``target_ess``: only as
        many proposals (at most ``count``) as the last trial's ESS per proposal says reach
        it. ``rescue``: where the first trial's k̂ exceeds :data:`PARETO_K_LIMIT` (its
        weighted moments then rest on a few proposals), the proposal it gives instead
        (:meth:`newton_proposal`)."""
        rounds, best = 0, None
        for rounds in range(ADAPT_ROUNDS + 1):
            trial = self.weighted(data, proposal, min(count, ADAPT_DRAWS), rng)
            ess = kish_ess(trial.log_weights)
            score = (max(trial.pareto_k, ADAPT_K), -ess)  # k̂ first, then the ESS
            if best is None or score < best[0]:
                best = (score, trial, proposal)
            if (trial.pareto_k <= ADAPT_K and ess >= ADAPT_ESS * len(trial.points)) or (
                rounds == ADAPT_ROUNDS
            ):
                break
            # a heuristic, not a reliability test: above 0.7 whatever the trial's size, the
            # weighted moments rest on a few proposals and the variant lies away from them
            far = rounds == 0 and rescue is not None and trial.pareto_k > PARETO_K_LIMIT
            rescued = rescue() if far else None
            proposal = rescued or Proposal.weighted(trial.points, trial.log_weights)
        _, trial, proposal = best
        drawn = len(trial.points)
        if target_ess is not None:
            needed = np.ceil(target_ess * drawn / kish_ess(trial.log_weights))
            count = int(np.clip(needed, drawn, count))
        final = trial if count <= drawn else self.weighted(data, proposal, count, rng)
        return dataclasses.replace(final, rounds=rounds)

    def sample(
        self,
        data,
        *,
        chains: int,
        draws: int,
        seed: int,
        start: Proposal | None = None,
        proposals: int | None = None,
        target_ess: float | None = None,
        rescue: Callable[[], Proposal | None] | None = None,
    ) -> Draws | Refused:
        """Draws of the posterior with ``data`` (module docstring): ``proposals`` (default
        ``chains`` × ``draws``; with ``target_ess`` at most as many,
        :meth:`adapted_sample`) proposals resampled into ``chains`` × ``draws`` draws; or,
        where the approximation is refused, why (:class:`Refused`, for the caller's fallback).
        ``start``: the first proposal (:func:`importance_refit`) in place of the Student-t at
        the mode with scale H⁻¹, whose searches are then skipped; ``rescue``: as in
        :meth:`adapted_sample`."""
        rng = np.random.default_rng(seed)
        started = time.perf_counter()
        fit, count = None, proposals or chains * draws
        with compile_clock() as compiled:
            if start is None:
                fit = self.fit(data, seed)
                if fit.refusal is not None:
                    return Refused(fit.refusal)
                start = Proposal(fit.mode, np.linalg.inv(fit.hessian))
            sample = self.adapted_sample(data, start, count, rng, target_ess, rescue)
            count = len(sample.points)
            if not sample.pareto_k <= pareto_k_limit(count):
                return Refused(
                    f"the importance weights have Pareto k {sample.pareto_k:.2f} > "
                    f"{pareto_k_limit(count):.2f} after {sample.rounds} adaptations"
                )
            chosen = _resampled(sample.log_weights, chains, draws, rng)
            unique, inverse = np.unique(chosen, return_inverse=True)
            sites = self.constrained(data, sample.points[unique])
        seconds = {"compile": compiled[0]}
        seconds["sampling"] = time.perf_counter() - started - compiled[0]
        extra = {
            "pareto_k": sample.pareto_k,
            "adaptations": sample.rounds,
            "ess": kish_ess(sample.log_weights),
            "proposals": int(count),
            "distinct_draws": int(unique.size),
        }
        if fit is not None:
            extra["mode_searches"] = {
                "potentials": (fit.potentials - fit.potentials.min()).tolist(),
                "distances": fit.distances.tolist(),
            }
        return Draws(
            sites={
                name: values[inverse].reshape(chains, draws, *values.shape[1:])
                for name, values in sites.items()
            },
            stats={"lp": -sample.potentials[chosen].reshape(chains, draws)},
            sampler="laplace",
            settings={"chains": chains, "draws": draws, "seed": seed},
            seconds=seconds,
            extra=extra,
            program=self,
            unconstrained=sample.points[chosen].reshape(chains, draws, -1),
        )


def importance_refit(
    draws: Draws,
    model: PosteriorModel,
    data,
    *,
    chains: int,
    count: int,
    seed: int,
    proposals: int | None = None,
    target_ess: float | None = None,
) -> Draws | Refused:
    """Draws of a variant of a run's posterior — ``model`` (the run's structure) with
    ``data`` (a row left out, an error scale set to zero) — by importance sampling from a
    Student-t with the mean and covariance of the run's draws, adapted and checked by PSIS
    as a Laplace run's own proposals (:meth:`LaplaceProgram.sample` with ``start``;
    ``proposals`` of them at most, default ``chains`` × ``count``, fewer where
    ``target_ess`` is reached sooner, resampled into ``chains`` × ``count`` draws): the
    variant's posterior mostly lies within a few of the run's standard deviations of it, so
    the mode searches are not needed, and k̂ above :func:`pareto_k_limit` says where that
    fails (then the caller samples the variant anew). :class:`Refused` where the run kept no
    unconstrained draws or the variant's space is not the run's. A NUTS run's variants are
    reweighted by a Laplace program of each variant structure, made once and kept on the
    run's NUTS program (``_reweighters``). Where the
    first trial's k̂ says the variant lies away from the run's draws, the proposal moves to
    its mode by Newton steps from their mean (:meth:`LaplaceProgram.newton_proposal`)."""
    if draws.unconstrained is None:
        return Refused("the run kept no unconstrained draws")
    points = draws.unconstrained.reshape(-1, draws.unconstrained.shape[-1])
    # a NUTS run's reweighting programs, one per variant structure, kept on its program
    kept = [] if draws.program is None else draws.program.__dict__.setdefault("_reweighters", [])
    candidates = [draws.program, *kept]
    program = next(
        (p for p in candidates if isinstance(p, LaplaceProgram) and p.serves(model)), None
    )
    if program is None:
        program = LaplaceProgram(model)
        if program.flat.dimension != points.shape[1]:
            return Refused("the variant's unconstrained space is not the run's")
        if draws.sampler == "nuts":
            kept.append(program)  # the next variant of the same structure reuses it
    start = Proposal.weighted(points, np.zeros(len(points)))
    return program.sample(
        data,
        chains=chains,
        draws=count,
        seed=seed,
        start=start,
        proposals=proposals,
        target_ess=target_ess,
        rescue=lambda: program.newton_proposal(data, start),
    )


def laplace_draws(
    model: PosteriorModel,
    *,
    chains: int,
    draws: int,
    seed: int,
    program: LaplaceProgram | None = None,
) -> Draws | Refused:
    """Draws of ``model``'s posterior by Laplace + PSIS (module docstring) through
    ``program`` where it serves ``model`` (:meth:`LaplaceProgram.sample`)."""
    with compile_clock() as compiled:
        if program is None or not program.serves(model):
            program = LaplaceProgram(model)
    result = program.sample(model.data, chains=chains, draws=draws, seed=seed)
    if isinstance(result, Refused):
        return result
    seconds = {**result.seconds, "compile": result.seconds["compile"] + compiled[0]}
    return dataclasses.replace(result, seconds=seconds)


def _resampled(log_weights: np.ndarray, chains: int, draws: int, rng) -> np.ndarray:
    """``chains`` × ``draws`` indices systematically resampled from all the proposals and
    shuffled (repeated draws do not sit side by side as if autocorrelated); the chains are
    exchangeable slices of one weighted set, so R-hat between them says nothing."""
    return rng.permutation(systematic_resample(log_weights, chains * draws, rng))
