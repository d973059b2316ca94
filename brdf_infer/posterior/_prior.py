"""Draws of a scene's physical prior and of data simulated from it.

The posterior model's prior is the scene's ``[priors]`` truncated to coatings that conserve
energy (:mod:`brdf_infer.model._energy`; the model's ``energy_conservation`` factor). NumPyro's
``Predictive`` draws each parameter from its own distribution and cannot see a factor, so the
draws here are made by rejection: draws of the untruncated model (``simulate`` mode: every
parameter from its prior, every noise effect, ``obs``) whose parameters break energy
conservation are dropped, and batches are drawn until ``count`` remain. Rejection keeps the
accepted draws independent and distributed as the truncated prior (and their ``obs`` as its
prior predictive); the order of acceptance is the order of the draws, so a seed always gives
the same set.

Families other than Eq. (7)'s are sampled under their own default priors, which are left as
they are (the scene's ``[priors]`` are Eq. (7)'s).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from numpyro.infer import Predictive

from brdf_infer._internal.stored_programs import StoredFunction
from brdf_infer.model import conserves_energy
from brdf_infer.posterior._model import ENERGY_SITE, PosteriorModel, model_identity

MAX_BATCHES = 50  # of twice the draws asked for; the bundled priors accept 63 %


def _simulated(
    model: PosteriorModel, count: int, key, sites: frozenset[str] | None = None
) -> dict[str, np.ndarray]:
    """``count`` draws of the untruncated model; ``sites``: only these (and the parameters),
    the rest — ``obs``, count × rows values — never computed (the compiled program drops what
    it does not return; the kept sites' values are the same)."""
    predictive = Predictive(model, num_samples=count)
    wanted = None if sites is None else sites | set(model.family.parameters)

    def simulate(k):
        draws = predictive(k, mode="simulate")
        return {n: v for n, v in draws.items() if wanted is None or n in wanted}

    identity = ("prior", model_identity(model), count, None if wanted is None else sorted(wanted))
    draws = jax.device_get(StoredFunction(simulate, identity)(key))
    return {name: values for name, values in draws.items() if name != ENERGY_SITE}


def accepted(model: PosteriorModel, draws: dict[str, np.ndarray]) -> np.ndarray:
    """Which draws (leading axis) the physical prior keeps (module docstring)."""
    count = len(next(iter(draws.values())))
    if not model.family.paper_parameters:
        return np.ones(count, bool)
    family = model.family
    physical = {name: jnp.asarray(draws[name]) for name in family.parameters}
    # one compiled program (op by op, each operation is a program of its own)
    check = jax.jit(lambda p: conserves_energy(family.as_params(p), family.constants_of(p)))
    return np.asarray(check(physical))


def prior_draws(
    model: PosteriorModel, count: int, seed: int, sites: frozenset[str] | None = None
) -> dict[str, np.ndarray]:
    """``count`` draws of every site of the physical prior and a simulated ``obs`` (ln R of
    every row) each, leading axis the draws; ``sites``: only these sites and the family's
    parameters (the same values; no count × rows ``obs`` computed or held).

    Raises:
        RuntimeError: fewer than ``count`` accepted after :data:`MAX_BATCHES` batches (a prior
            with almost no mass on coatings that conserve energy).
    """
    key = jax.random.PRNGKey(seed)
    kept: dict[str, list[np.ndarray]] = {}
    total = 0
    for batch in range(MAX_BATCHES):
        batch_key = key if batch == 0 else jax.random.fold_in(key, batch)
        draws = _simulated(model, 2 * count, batch_key, sites)
        keep = accepted(model, draws)
        for name, values in draws.items():
            kept.setdefault(name, []).append(np.asarray(values)[keep])
        total += int(keep.sum())
        if total >= count:
            return {name: np.concatenate(parts)[:count] for name, parts in kept.items()}
    raise RuntimeError(
        f"the scene's priors put almost no mass on coatings with TIS <= 1: {total} of "
        f"{2 * count * MAX_BATCHES} prior draws conserve energy"
    )
