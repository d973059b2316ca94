"""Least squares for any model family (ABg, Harvey–Shack, Lambertian, …) on a scene's rows.

Minimises Σ ((ln R_pred − ln R_obs)/σᵢ)² over the family's internal coordinates
(:class:`brdf_infer.model.ModelFamily`), with σᵢ each row's own noise under the scene's error
model and a fixed repeatability added in quadrature (a learned one and the random effects are
the posterior's business, as in :mod:`brdf_infer.lsq`; where some row would have no σ, the
fit is unweighted). Bounded coordinates are optimised
through smooth maps of the real line (a logistic for an interval, an exponential for a
one-sided bound). Multi-start (prior draws) Levenberg–Marquardt (optimistix), one compiled
solver vmapped over the starts; the 1σ of the physical parameters from the Gauss–Newton
covariance by the delta method.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from brdf_infer.error_model import value_sigma
from brdf_infer.fit_quality import FitQuality, scaled_sigma
from brdf_infer.measurements import Measurements
from brdf_infer.model import ModelFamily
from brdf_infer.observations import build_observation_model, log_reflectance
from brdf_infer.priors import Prior
from brdf_infer.scene import Scene
from brdf_infer.settings import LSQ_STARTS


def _from_real(prior: Prior, w):
    """The coordinate of a real number w under ``prior``'s support."""
    low, high = prior.lower, prior.upper
    if math.isfinite(low) and math.isfinite(high):
        return low + (high - low) * jax.nn.sigmoid(w)
    if math.isfinite(high):
        return high - jnp.exp(w)
    if math.isfinite(low):
        return low + jnp.exp(w)
    return w


def _to_real(prior: Prior, value: float) -> float:
    low, high = prior.lower, prior.upper
    if math.isfinite(low) and math.isfinite(high):
        fraction = min(max((value - low) / (high - low), 1e-6), 1 - 1e-6)
        return math.log(fraction / (1 - fraction))
    if math.isfinite(high):
        return math.log(max(high - value, 1e-12))
    if math.isfinite(low):
        return math.log(max(value - low, 1e-12))
    return value


@dataclass(frozen=True)
class FamilyFit:
    """A family's least-squares optimum (``as_json``: the JSON of ``fit --method lsq``)."""

    family: str
    params: dict[str, float]
    sigma: dict[str, float]
    cost: float
    n_points: int
    starts: int
    starts_converged: int
    seconds: float

    @property
    def quality(self) -> FitQuality:
        """χ²/dof and its statement (:mod:`brdf_infer.fit_quality`)."""
        return FitQuality(self.cost, self.n_points - len(self.params))

    def as_json(self, scene_name: str) -> dict[str, Any]:
        """``sigma``: the unscaled 1σ; ``sigma_scaled``: times √(χ²/dof)."""
        quality = self.quality
        return {
            "method": "lsq",
            "model": self.family,
            "scene": scene_name,
            "params": self.params,
            "sigma": self.sigma,
            "sigma_scaled": scaled_sigma(self.sigma, quality.sigma_factor),
            "cost": self.cost,
            "reduced_chi2": self.cost / max(self.n_points - len(self.params), 1),
            **quality.as_json(),
            "n_points": self.n_points,
            "starts": self.starts,
            "starts_converged": self.starts_converged,
            "seconds": self.seconds,
        }


def fit_family_lsq(
    scene: Scene,
    measurements: Measurements,
    member: ModelFamily,
    *,
    starts: int = LSQ_STARTS,
    seed: int = 0,
) -> FamilyFit:
    """Multi-start least squares of ``member`` on the scene's rows (module docstring)."""
    started = time.perf_counter()
    rows = build_observation_model(scene, measurements).data
    errors = scene.errors
    repeatability = 0.0 if errors.learns_repeatability else float(errors.repeatability)
    sigma = np.sqrt(value_sigma(errors, measurements) ** 2 + repeatability**2)
    sigma = jnp.asarray(sigma if np.all(sigma > 0) else np.ones_like(sigma))  # else unweighted
    priors = [c.prior for c in member.coordinates]

    def internal(w):
        return {c.site: _from_real(c.prior, w[k]) for k, c in enumerate(member.coordinates)}

    def residuals(w, _):
        mean = log_reflectance(member, member.to_physical(internal(w)), rows)
        return (mean - rows.log_reflectance) / sigma

    rng = np.random.default_rng(seed)
    start_points = np.array(
        [
            [
                _to_real(p, float(np.clip(rng.normal(p.loc, p.scale), p.lower, p.upper)))
                if p.kind != "uniform"
                else _to_real(p, float(rng.uniform(p.lower, p.upper)))
                for p in priors
            ]
            for _ in range(starts)
        ]
    )
    solver = optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10)

    @jax.jit
    def solve(w0):
        solution = optx.least_squares(residuals, solver, w0, max_steps=500, throw=False)
        return solution.value, jnp.sum(residuals(solution.value, None) ** 2)

    values, costs = jax.vmap(solve)(jnp.asarray(start_points))
    costs = np.asarray(costs)
    best = int(np.nanargmin(costs))
    w = values[best]
    converged = int(np.sum(np.abs(costs - costs[best]) <= 1e-6 * max(1.0, costs[best])))
    jacobian = jax.jacfwd(lambda v: residuals(v, None))(w)
    covariance = jnp.linalg.pinv(jacobian.T @ jacobian)
    physical_of = jax.jit(
        lambda v: jnp.stack([member.to_physical(internal(v))[n] for n in member.parameters])
    )
    gradient = jax.jacfwd(physical_of)(w)
    variances = jnp.diag(gradient @ covariance @ gradient.T)
    physical = np.asarray(physical_of(w))
    return FamilyFit(
        family=member.name,
        params={n: float(v) for n, v in zip(member.parameters, physical, strict=True)},
        sigma={
            n: float(np.sqrt(max(v, 0.0)))
            for n, v in zip(member.parameters, np.asarray(variances), strict=True)
        },
        cost=float(costs[best]),
        n_points=len(measurements),
        starts=starts,
        starts_converged=converged,
        seconds=time.perf_counter() - started,
    )
