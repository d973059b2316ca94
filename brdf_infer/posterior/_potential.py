"""A :class:`PosteriorModel` on its flat unconstrained space: potential, constraining, starts.

Built from NumPyro's public transforms (``potential_energy``, ``constrain_fn``,
``unconstrain_fn``) with the data as an argument; nothing here runs the model eagerly (the
shapes come from ``jax.eval_shape``), so building it costs no compilation.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree
from numpyro import handlers
from numpyro.infer import init_to_uniform
from numpyro.infer.util import constrain_fn, potential_energy, unconstrain_fn

from brdf_infer.posterior._likelihood import ModelData
from brdf_infer.posterior._model import PosteriorModel

INIT_RADIUS = 2.0  # NumPyro's init_to_uniform range on the unconstrained space


def unconstrained_prototype(model: PosteriorModel, data: ModelData) -> dict:
    """One point of the model's unconstrained space (for its shapes; traced, not run)."""
    seeded = handlers.substitute(handlers.seed(model, 0), substitute_fn=init_to_uniform)
    trace = handlers.trace(seeded).get_trace(data)
    params = {
        name: site["value"]
        for name, site in trace.items()
        if site["type"] == "sample" and not site["is_observed"]
    }
    return unconstrain_fn(model, (data,), {}, params)


class FlatPotential:
    """The model's potential (−log density) and constraining map on a flat vector.

    The flat layout (:attr:`dimension`, :meth:`unravel`) is found by tracing the model
    abstractly, on first use: a run whose programs are loaded from disk never needs it
    (≈ 0.7 s of a warm run on the bundled scene).

    Attributes:
        model: the posterior model.
    """

    def __init__(self, model: PosteriorModel):
        self.model = model

    @functools.cached_property
    def _layout(self) -> tuple[int, Callable]:
        model = self.model
        template = jax.eval_shape(lambda data: unconstrained_prototype(model, data), model.data)
        flat, unravel = ravel_pytree(
            jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), template)
        )
        return int(flat.size), unravel

    @property
    def dimension(self) -> int:
        """Length of the flat unconstrained vector."""
        return self._layout[0]

    def unravel(self, flat_z: jnp.ndarray) -> dict:
        """The model's unconstrained sites from the flat vector ``flat_z``."""
        return self._layout[1](flat_z)

    def potential(self, flat_z: jnp.ndarray, data: ModelData) -> jnp.ndarray:
        """−log p(z, data) on the unconstrained space (Jacobians included)."""
        return potential_energy(self.model, (data,), {}, self.unravel(flat_z))

    def constrain(self, flat_z: jnp.ndarray, data: ModelData) -> dict:
        """Every sampled and deterministic site of the model at ``flat_z``."""
        return constrain_fn(
            self.model, (data,), {}, self.unravel(flat_z), return_deterministic=True
        )

    def best_of_uniform(self, key, data: ModelData, count: int) -> jnp.ndarray:
        """The lowest-potential of ``count`` points uniform in [−2, 2]^d (traceable)."""
        candidates = jax.random.uniform(
            key, (count, self.dimension), minval=-INIT_RADIUS, maxval=INIT_RADIUS
        )
        energies = jax.vmap(lambda x: self.potential(x, data))(candidates)
        energies = jnp.where(jnp.isfinite(energies), energies, jnp.inf)
        return candidates[jnp.argmin(energies)]

    def search(self, key, data: ModelData, tolerance: float, max_steps: int):
        """BFGS (optimistix, relative and absolute ``tolerance``) on the potential from the best
        of 4 uniform points (traceable): the end, its potential, and whether it converged."""
        import optimistix as optx  # imported only by the runs that search a mode

        start = self.best_of_uniform(key, data, 4)
        solution = optx.minimise(
            lambda x, _: self.potential(x, data),
            optx.BFGS(rtol=tolerance, atol=tolerance),
            start,
            max_steps=max_steps,
            throw=False,
        )
        converged = solution.result == optx.RESULTS.successful
        return solution.value, self.potential(solution.value, data), converged
