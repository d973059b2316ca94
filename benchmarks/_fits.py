"""Benchmark of fits on one set of residuals: paper regression, optimistix, SciPy."""

from __future__ import annotations

import time
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from scipy.optimize import least_squares

from benchmarks._timing import timed
from brdf_infer.fit.lsq import fit_lsq, fit_space, internal_bounds, start_points
from brdf_infer.fit.paper import paper_fit
from brdf_infer.model import family
from brdf_infer.model.coordinates import from_internal
from brdf_infer.model.params import UV_PAPER, VIS_PAPER
from brdf_infer.predict.observations import build_observation_model
from brdf_infer.scene import Scene
from brdf_infer.studies.synthetic import synthetic_measurements
from brdf_infer.tables.measurements import Measurements


@dataclass(frozen=True)
class FitRow:
    scene: str
    method: str
    cost: float
    starts_at_best: str
    seconds: float
    compile_seconds: float


def _scipy_rows(
    scene: Scene, data: Measurements, label: str, starts: int, row_sigma: np.ndarray
) -> FitRow:
    """SciPy's trust-region-reflective least_squares, the same residuals, weights and starts."""
    model = build_observation_model(scene, data).with_sigma(row_sigma)
    space = fit_space(scene, family(scene.model.family, scene.model.fold, scene.model.constants))
    transform, free_index = space.transform, space.free_index

    def residuals(z_free):
        return model.residuals(from_internal(transform.free_to_full(z_free, free_index)))

    residual_fn = jax.jit(residuals)
    jacobian_fn = jax.jit(jax.jacfwd(residuals))
    bounds = [internal_bounds(scene, name) or (-np.inf, np.inf) for name in scene.free_parameters]
    lower, upper = np.array([b[0] for b in bounds]), np.array([b[1] for b in bounds])
    points = start_points(scene, space, starts, 0)
    clock = time.perf_counter()
    jax.block_until_ready(
        (residual_fn(jnp.asarray(points[0])), jacobian_fn(jnp.asarray(points[0])))
    )
    compile_seconds = time.perf_counter() - clock
    clock = time.perf_counter()
    costs = []
    for start in points:
        solution = least_squares(
            lambda z: np.asarray(residual_fn(jnp.asarray(z))),
            start,
            jac=lambda z: np.asarray(jacobian_fn(jnp.asarray(z))),
            bounds=(lower, upper),
            method="trf",
            xtol=1e-12,
            ftol=1e-12,
            gtol=1e-12,
        )
        costs.append(2.0 * solution.cost)  # SciPy's cost is ½Σr²
    seconds = time.perf_counter() - clock
    costs = np.array(costs)
    best = costs.min()
    at_best = int(np.sum(np.abs(costs - best) <= 1e-6 * max(1.0, best)))
    return FitRow(
        label, "scipy least_squares (trf)", best, f"{at_best}/{starts}", seconds, compile_seconds
    )


def _scenes(scene: Scene, measurements: Measurements) -> list[tuple[str, Measurements]]:
    return [
        (f"{scene.name} (bundled data)", measurements),
        (
            "synthetic uv-paper, 6.5 % noise",
            synthetic_measurements(scene, measurements, UV_PAPER, noise_rel=0.065, seed=0),
        ),
        ("synthetic vis-paper, noise-free", synthetic_measurements(scene, measurements, VIS_PAPER)),
    ]


def fit_rows(scene: Scene, measurements: Measurements, quick: bool) -> list[FitRow]:
    """Final χ² against time for every fit method and scene, every method weighted by the
    row σ that least squares with Levenberg–Marquardt settled on."""
    starts = 4 if quick else 16
    rows = []
    for label, data in _scenes(scene, measurements)[: 2 if quick else 3]:
        row_sigma = None
        solver_rows = []
        for solver in ("lm", "gauss-newton", "dogleg"):
            result = fit_lsq(scene, data, starts=starts, solver=solver)
            row_sigma = result.row_sigma if row_sigma is None else row_sigma
            solver_rows.append(
                FitRow(
                    label,
                    f"optimistix {solver} (vmapped starts)",
                    result.cost,
                    f"{result.starts_converged}/{starts}",
                    result.seconds,
                    result.compile_seconds,
                )
            )
        model = build_observation_model(scene, data).with_sigma(row_sigma)
        regression, compile_seconds, seconds = timed(paper_fit, scene, data)
        cost = float(model.chi2(regression.params))
        label_paper = "paper regression (alpha, theta_s0 fixed)"
        rows.append(FitRow(label, label_paper, cost, "-", seconds, compile_seconds))
        rows += solver_rows
        rows.append(_scipy_rows(scene, data, label, starts, row_sigma))
    return rows
