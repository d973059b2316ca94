"""One refitter: the posterior of a run's model with other data, or of a variant of the model,
drawn anew where the run's own draws cannot be reweighted to it.

Two jobs need it: exact leave-one-out where PSIS-LOO's Pareto k̂ is too high (the run's model
with a row left out, :mod:`._loo_refit`) and the width attribution where an alternative's
importance weights are (a variant of the model with an assumption removed, :mod:`._width`).
Both go the same way, :func:`refit`:

1. importance sampling from the run's draws (:func:`~._laplace.importance_refit`: a Student-t
   with their mean and covariance, adapted, moved to the variant's mode by Newton steps where
   it lies away; Pareto k̂ ≤ :func:`~brdf_infer.verdict.pareto_k_limit` of the proposals
   checked; at most :data:`PROPOSALS_PER_DRAW` proposals per effective draw aimed at, Kish's
   ESS :data:`REFIT_ESS`);
2. where that is refused, the run's sampler through the run's compiled program where it serves
   the refit's model (:meth:`~._nuts.NutsProgram.serves`: a variant whose options are data, or
   a row left out, compiles nothing): NUTS with the run's warmup and target acceptance from
   the run's seed, or Laplace + PSIS (whose own Pareto k̂ refuses it);
3. :class:`~._samplers.Refused` with the reason where every way is refused: an emcee run (no
   compiled program), or a NUTS refit that fails the one convergence rule,
   :func:`convergence_failure` (a divergent transition, or R-hat above the run's threshold on
   a scalar site: a refit that has not converged would turn a failure into a fact).

A NUTS run's exact-LOO rows skip step 1 (``importance=False``): on the bundled rows, whose
posterior is far from normal, the Student-t's Kish ESS is ≈ 25 % of its proposals and the
influential row's exact term varied by ±0.08 between seeds against NUTS's ±0.01.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from brdf_infer._internal import arviz as az
from brdf_infer.posterior._laplace import LaplaceProgram, importance_refit
from brdf_infer.posterior._likelihood import ModelData
from brdf_infer.posterior._model import PosteriorModel
from brdf_infer.posterior._nuts import NutsProgram, chain_keys
from brdf_infer.posterior._results import THRESHOLDS
from brdf_infer.posterior._samplers import Draws, Refused, program_draws

# draws per chain of a refit (at most the run's), the run's chains: an exact-LOO term, a log
# mean over the refit's draws of one row's density, to ±0.01 between seeds on the bundled
# influential row (4 × 1000 NUTS draws)
REFIT_DRAWS = 1000
# a width variant's refit: 2 × 500 draws, ESS ≈ 800 for the 95 % ends on lya, put the Monte
# Carlo standard error of a width ratio near 0.03 (brdf_infer.posterior._width); a new
# posterior of every parameter for each variant, where an exact-LOO refit is one of at most
# five rows, so the fewer draws of the two
VARIANT_CHAINS, VARIANT_DRAWS = 2, 500
# Kish's ESS an importance refit aims at (at most the draws it is resampled into): the width
# variant's 2 × 500 draws, and the 1000 draws of one chain of an exact-LOO refit
REFIT_ESS = 1000
# proposals at most per effective draw aimed at: a variant's posterior narrower than the run's
# leaves a quarter of them effective (ESS 260 of 1000 without the calibration on lya), a large
# table's about half
PROPOSALS_PER_DRAW = 4


class Refit(NamedTuple):
    """A refit's draws and how they were drawn.

    Attributes:
        draws: the draws (chains, draws, ...), equally weighted.
        record: ``chains``, ``draws``, ``sampler`` (``"importance"``, ``"nuts"`` with its
            ``warmup``, or ``"laplace"``) and, of an importance refit, its ``pareto_k`` and
            Kish's ``ess``.
    """

    draws: Draws
    record: dict[str, int | str | float]


def convergence_failure(sites: dict[str, np.ndarray], stats: dict[str, np.ndarray]) -> str | None:
    """Why an MCMC refit's chains are not to be used, in words, or None: a divergent
    transition, or R-hat (ArviZ's rank-normalised split R-hat) above the run's threshold
    (:data:`~brdf_infer.posterior._results.THRESHOLDS`, 1.01) on a scalar site that varies.
    The one convergence rule of every refit."""
    divergences = int(np.sum(np.asarray(stats["diverging"])))
    if divergences:
        return f"{divergences} divergent transitions"
    scalars = {name: v for name, v in sites.items() if np.ndim(v) == 2 and np.ptp(v) > 0}
    if not scalars:
        return None
    r_hat = az.rhat(az.from_dict(posterior=scalars))
    worst = max(scalars, key=lambda name: float(r_hat[name]))
    if not float(r_hat[worst]) <= THRESHOLDS["r_hat"]:
        return f"R-hat {float(r_hat[worst]):.3f} > {THRESHOLDS['r_hat']} ({worst})"
    return None


def refit(
    draws: Draws,
    model: PosteriorModel,
    data: ModelData | None = None,
    *,
    chains: int | None = None,
    count: int = REFIT_DRAWS,
    seed: int | None = None,
    importance: bool = True,
) -> Refit | Refused:
    """The posterior of ``model`` with ``data`` (default its own) from a run's ``draws``
    (module docstring): importance sampling from them, else the run's compiled program, else
    :class:`Refused`.

    Args:
        draws: the run's draws (their program, settings and unconstrained draws).
        model: the refit's model: the run's own (with ``data``) or a variant of it.
        data: other data of the run's own model (a row left out), which the run's program
            samples as it is (the same shapes, nothing compiled); None: ``model`` is a variant
            with its own data, sampled through the run's program where that serves it
            (:meth:`~._nuts.NutsProgram.serves`), else through one compiled for it.
        chains: chains of the refit (default and at most the run's).
        count: draws per chain (at most the run's): :data:`REFIT_DRAWS` for an exact-LOO
            term; the width's variants ask for :data:`VARIANT_CHAINS` × :data:`VARIANT_DRAWS`,
            enough for a width ratio to ±0.03 at half the time of each of their several refits.
        seed: the refit's seed (default the run's).
        importance: try importance sampling first (False for a NUTS run's exact LOO: module
            docstring).
    """
    settings = draws.settings
    if draws.sampler not in ("nuts", "laplace") or draws.program is None:
        return Refused(f"a {draws.sampler} run keeps no compiled program to refit with")
    own = data is not None  # the run's own model: its program serves it
    data = model.data if data is None else data
    chains = min(chains or settings["chains"], settings["chains"])
    count = min(count, settings["draws"])
    seed = settings["seed"] if seed is None else seed
    shape = {"chains": chains, "draws": count}
    if importance:
        target = min(REFIT_ESS, chains * count)
        sampled = importance_refit(
            draws,
            model,
            data,
            chains=chains,
            count=count,
            seed=seed,
            proposals=PROPOSALS_PER_DRAW * target,
            target_ess=target,
        )
        if not isinstance(sampled, Refused):
            extra = {"pareto_k": sampled.extra["pareto_k"], "ess": sampled.extra["ess"]}
            return Refit(sampled, {**shape, "sampler": "importance", **extra})
    if draws.sampler == "laplace":
        program = draws.program
        if not (own or program.serves(model)):
            program = LaplaceProgram(model)
        sampled = program.sample(data, chains=chains, draws=count, seed=seed)
        if isinstance(sampled, Refused):
            return sampled
        return Refit(sampled, {**shape, "sampler": "laplace"})
    return _nuts_refit(draws, model, data if own else None, chains, count, seed)


def _nuts_refit(
    draws: Draws, model: PosteriorModel, data: ModelData | None, chains: int, count: int, seed: int
) -> Refit | Refused:
    """NUTS with the run's warmup and target acceptance, through the run's program for its
    own model's ``data`` or where it serves the variant ``model`` (``data`` None); refused
    where the chains fail :func:`convergence_failure`."""
    warmup, target_accept = draws.settings["warmup"], draws.settings["target_accept"]
    program = draws.program
    if data is None and not program.serves(model, warmup, target_accept):
        program = NutsProgram(model, warmup=warmup, target_accept=target_accept)
    data = model.data if data is None else data
    output = program.run(data, chain_keys(seed, 1, chains)[0], count)
    failure = convergence_failure(output.sites, output.stats)
    if failure is not None:
        return Refused(f"the NUTS refit failed its checks: {failure}")
    sampled = program_draws(program, output, chains=chains, draws=count, seed=seed)
    record = {"chains": chains, "draws": count, "warmup": warmup, "sampler": "nuts"}
    return Refit(sampled, record)
