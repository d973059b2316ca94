"""The coordinates least squares (:mod:`brdf_infer.fit.lsq`) solves in, for every model family.

A family's internal coordinates z are well conditioned (:class:`brdf_infer.model.ModelFamily`);
the solver works on an unconstrained vector u of the free ones:

* Eq. (7)'s family: z = (ln brdf0, b1, b2, b3, α, θs0/90°) (:mod:`brdf_infer.model.coordinates`),
  the scene's fixed parameters held at their values, α and θs0 squashed into the bounds of the
  scene's ``[priors]`` by a logistic; starts drawn uniformly from the priors' start ranges.
* The other families: their own coordinates (ln(A/B), ln ρ_k, g for ABg, …), a coordinate
  bounded on both sides through a logistic, on one side through an exponential; starts drawn
  from the coordinates' default priors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer.model import ModelFamily, Physical
from brdf_infer.model.coordinates import ANGLE_SCALE_DEG, INTERNAL_NAMES, from_internal, to_internal
from brdf_infer.model.params import PARAM_NAMES, Params
from brdf_infer.model.priors import DEFAULT_BOUNDS
from brdf_infer.scene import Scene

UNBOUNDED, INTERVAL, ABOVE, BELOW = 0, 1, 2, 3  # a free coordinate's support: ℝ, [l, u], > l, < u


class FreeTransform(NamedTuple):
    """Free unconstrained vector u ↔ full internal vector z (fixed entries filled in).

    A pytree of arrays, so that one compiled solver serves every dataset of the same shape.
    """

    base: jnp.ndarray  # full internal vector holding the fixed values
    lower: jnp.ndarray  # bounds of the free entries (unused where not bounded)
    upper: jnp.ndarray
    kind: jnp.ndarray  # UNBOUNDED, INTERVAL, ABOVE or BELOW per free entry

    @property
    def bounded(self) -> jnp.ndarray:
        """The free entries bounded on both sides."""
        return self.kind == INTERVAL

    def free_to_full(self, z_free: jnp.ndarray, free_index: tuple[int, ...]) -> jnp.ndarray:
        return self.base.at[np.array(free_index, int)].set(z_free)

    def to_free(self, u: jnp.ndarray) -> jnp.ndarray:
        squashed = self.lower + (self.upper - self.lower) * jax.nn.sigmoid(u)
        one_sided = self.kind >= ABOVE
        distance = jnp.exp(jnp.where(one_sided, u, 0.0))  # double where: no overflow elsewhere
        bounded_one_side = jnp.where(
            self.kind == ABOVE, self.lower + distance, self.upper - distance
        )
        return jnp.where(self.bounded, squashed, jnp.where(one_sided, bounded_one_side, u))

    def from_free(self, z_free: np.ndarray) -> np.ndarray:
        lower, upper = np.asarray(self.lower), np.asarray(self.upper)
        kind = np.asarray(self.kind)
        z_free = np.asarray(z_free, float)
        span = np.where(kind == INTERVAL, upper - lower, 1.0)
        fraction = np.clip((z_free - lower) / span, 1e-9, 1 - 1e-9)
        logit = np.log(fraction) - np.log1p(-fraction)
        above = np.log(np.maximum(z_free - lower, 1e-12))
        below = np.log(np.maximum(upper - z_free, 1e-12))
        return np.select(
            [kind == INTERVAL, kind == ABOVE, kind == BELOW], [logit, above, below], z_free
        )


@dataclass(frozen=True)
class FitSpace:
    """What least squares solves for (module docstring).

    Attributes:
        member: the family fitted.
        names: the internal coordinates, fixed ones included.
        free_index: positions of the fitted coordinates in ``names``.
        free: the fitted physical parameters.
        transform: the map between the solver's vector and the internal coordinates.
    """

    member: ModelFamily
    names: tuple[str, ...]
    free_index: tuple[int, ...]
    free: tuple[str, ...]
    transform: FreeTransform


def physical_of(member: ModelFamily, z_full) -> Physical:
    """The physical parameters of the full internal vector ``z_full`` (module docstring)."""
    if member.paper_parameters:
        return from_internal(z_full)._asdict()
    return member.to_physical({c.site: z_full[k] for k, c in enumerate(member.coordinates)})


def internal_bounds(scene: Scene, name: str) -> tuple[float, float] | None:
    """Internal-coordinate bounds of Eq. (7)'s bounded parameters (α, θs0), else None."""
    if name not in DEFAULT_BOUNDS:
        return None
    prior = scene.priors[name]
    lower, upper = prior.lower, prior.upper
    default = DEFAULT_BOUNDS[name]
    lower = lower if np.isfinite(lower) else default[0]
    upper = upper if np.isfinite(upper) else default[1]
    scale = ANGLE_SCALE_DEG if name == "theta_s0" else 1.0
    return lower / scale, upper / scale


def fit_space(scene: Scene, member: ModelFamily) -> FitSpace:
    """The coordinates ``member`` is fitted in on ``scene`` (module docstring)."""
    if member.paper_parameters:
        fixed = Params(
            *(scene.priors[name].value if scene.priors[name].fixed else 1.0 for name in PARAM_NAMES)
        )
        bounds = [internal_bounds(scene, name) for name in scene.free_parameters]
        return FitSpace(
            member,
            INTERNAL_NAMES,
            tuple(PARAM_NAMES.index(name) for name in scene.free_parameters),
            scene.free_parameters,
            FreeTransform(
                base=to_internal(fixed),
                lower=jnp.array([b[0] if b else 0.0 for b in bounds]),
                upper=jnp.array([b[1] if b else 1.0 for b in bounds]),
                kind=jnp.array([INTERVAL if b else UNBOUNDED for b in bounds]),
            ),
        )
    priors = [c.prior for c in member.coordinates]
    lower = [p.lower if math.isfinite(p.lower) else 0.0 for p in priors]
    upper = [p.upper if math.isfinite(p.upper) else 1.0 for p in priors]
    kind = [_support(p.lower, p.upper) for p in priors]
    return FitSpace(
        member,
        tuple(c.site for c in member.coordinates),
        tuple(range(len(priors))),
        member.parameters,
        FreeTransform(
            base=jnp.zeros(len(priors)),
            lower=jnp.array(lower),
            upper=jnp.array(upper),
            kind=jnp.array(kind),
        ),
    )


def _support(lower: float, upper: float) -> int:
    if math.isfinite(lower) and math.isfinite(upper):
        return INTERVAL
    if math.isfinite(lower):
        return ABOVE
    if math.isfinite(upper):
        return BELOW
    return UNBOUNDED


def start_points(
    scene: Scene, space: FitSpace, starts: int, seed: int, init: Params | None = None
) -> np.ndarray:
    """Starting internal free vectors (starts × free), module docstring; ``init`` (Eq. 7's
    family only): the first start.

    Raises:
        ValueError: ``init`` for another family.
    """
    rng = np.random.default_rng(seed)
    if not space.member.paper_parameters:
        if init is not None:
            raise ValueError(f"a start for {space.member.name} is drawn from its priors")
        priors = [c.prior for c in space.member.coordinates]
        return np.array([[_prior_start(rng, p) for p in priors] for _ in range(starts)]).reshape(
            starts, len(priors)
        )
    transform = space.transform
    columns = []
    for position, name in enumerate(space.free):
        low, high = scene.priors[name].start_range()
        if name == "theta_s0":
            low, high = low / ANGLE_SCALE_DEG, high / ANGLE_SCALE_DEG
        if transform.bounded[position]:
            low = max(low, transform.lower[position])
            high = min(high, transform.upper[position])
            span = high - low
            low, high = low + 0.02 * span, high - 0.02 * span
        columns.append(rng.uniform(low, high, starts))
    points = np.stack(columns, 1)
    if init is not None:
        points[0] = np.asarray(to_internal(init))[list(space.free_index)]
    return points


def _prior_start(rng: np.random.Generator, prior) -> float:
    """A start drawn from a coordinate's prior, kept 2 % of its scale (or span) inside its
    bounds: a start on a bound would sit where its map to the real line is flat."""
    if prior.kind == "uniform":
        return float(rng.uniform(prior.lower, prior.upper))
    margin = 0.02 * prior.scale
    return float(
        np.clip(rng.normal(prior.loc, prior.scale), prior.lower + margin, prior.upper - margin)
    )
