"""Benchmark of TIS quadratures, Eq. (9): 2-D midpoint, 2-D Gauss–Legendre, exact 1-D.

With Eq. (10)'s folding throughout (``FOLD``), as in the article's Table 3: its shoulder at θsf
is the harder integrand (a third panel for the 1-D rule), so the errors bound those of the
unfolded TIS that the products use by default."""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks._timing import timed
from brdf_infer._internal.units import DEG
from brdf_infer.model import log_brdf_hemisphere, tis
from brdf_infer.model.params import UV_PAPER, Params

THETA_I = np.array([5.0, 30.0, 50.0, 70.0])
FOLD = True


@dataclass(frozen=True)
class TisRow:
    method: str
    resolution: str
    evaluations: int  # BRDF evaluations per TIS
    max_rel_error: float
    seconds_per_tis: float
    compile_seconds: float


def _grid_tis(theta_nodes, theta_weights, phi_nodes, phi_weights, theta_i, params):
    """Eq. (9) as written on a tensor grid (nodes in degrees, weights in radians)."""
    theta, phi = theta_nodes[:, None], phi_nodes[None, :]
    brdf = jnp.exp(log_brdf_hemisphere(theta_i, theta, phi, params, FOLD))
    projected = 0.5 * jnp.sin(2.0 * theta * DEG)
    return jnp.sum(theta_weights[:, None] * phi_weights[None, :] * brdf * projected)


def _midpoint(n: int, upper: float):
    edges = np.linspace(0.0, upper, n + 1)
    return 0.5 * (edges[1:] + edges[:-1]), np.full(n, upper / n * DEG)


def _gauss(n: int, upper: float):
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * upper * (x + 1.0), 0.5 * upper * w * DEG


def _two_dimensional(rule, n_theta: int, params: Params):
    theta = tuple(map(jnp.asarray, rule(n_theta, 90.0)))
    phi = tuple(map(jnp.asarray, rule(4 * n_theta, 360.0)))
    single = partial(_grid_tis, *theta, *phi, params=params)
    return jax.jit(jax.vmap(single))


def tis_rows(quick: bool, params: Params = UV_PAPER) -> list[TisRow]:
    """Max relative error over θi = 5, 30, 50, 70° against the converged value, and time."""
    reference = np.asarray(tis(THETA_I, params, FOLD, nodes=256))
    rows = []
    grid_sizes = (45, 90, 180) if quick else (45, 90, 180, 360, 720)
    for label, rule in (("2-D midpoint", _midpoint), ("2-D Gauss-Legendre", _gauss)):
        sizes = grid_sizes if label == "2-D midpoint" else (8, 16, 32, 64, 128)[: 4 if quick else 5]
        for n in sizes:
            function = _two_dimensional(rule, n, params)
            values, compile_s, run_s = timed(function, jnp.asarray(THETA_I), repeat=3)
            error = np.max(np.abs(np.asarray(values) / reference - 1))
            rows.append(
                TisRow(label, f"{n} x {4 * n}", 4 * n * n, error, run_s / THETA_I.size, compile_s)
            )
    for nodes in (4, 8, 16, 32, 64):
        function = jax.jit(partial(tis, params=params, fold=FOLD, nodes=nodes))
        values, compile_s, run_s = timed(function, jnp.asarray(THETA_I))
        error = np.max(np.abs(np.asarray(values) / reference - 1))
        rows.append(
            TisRow(
                "exact 1-D (this package)",
                f"3 panels x {nodes}",
                3 * 2 * nodes,
                error,
                run_s / THETA_I.size,
                compile_s,
            )
        )
    return rows


def batched_throughput(quick: bool, params: Params = UV_PAPER) -> tuple[int, float, float]:
    """(number of TIS values, seconds, compile seconds) for TIS over draws × θi in one call."""
    draws = 500 if quick else 4000
    rng = np.random.default_rng(0)
    batch = Params(
        *(np.asarray(value) * (1 + 0.01 * rng.standard_normal(draws)) for value in params)
    )
    theta_i = jnp.linspace(0.0, 89.0, 90)
    _, compile_s, run_s = timed(jax.jit(partial(tis, fold=FOLD)), theta_i, batch, repeat=2)
    return draws * theta_i.size, run_s, compile_s
