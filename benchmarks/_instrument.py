"""Benchmark of the instrument kernels: accuracy against the number of nodes (against the
full cubature and the ray tracer), likelihood cost, NUTS ESS per second, and the synthetic
bias experiment with several seeds."""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer._internal import arviz as az
from brdf_infer.instrument import (
    DEFAULT_CANDIDATES,
    NODE_SHAPES,
    beam_geometry,
    build_kernel,
    clear_row_kernel_cache,
    kernel_log_reflectance,
    measurement_nodes,
    sobol_uniforms,
)
from brdf_infer.model import log_brdf_hemisphere
from brdf_infer.model.params import PARAM_NAMES, UV_PAPER, Params
from brdf_infer.predict.observations import build_observation_model
from brdf_infer.scene import Scene, check_instrument

OTHER = Params(0.006, 2e-4, -1e-9, 5e-12, 3.5, -20.0)
NODE_HEADERS = [
    "instrument",
    "nodes per row",
    "build [s]",
    "max error vs full cubature [%]",
    "max |kernel − ray tracer| / ray tracer [%]",
    "ray tracer MC σ (max) [%]",
    "ln R + gradient, 42 rows [µs]",
]
ESS_HEADERS = [
    "instrument",
    "min ESS bulk",
    "sampling [s]",
    "min ESS / s",
    "of point",
    "divergences",
    "compile [s]",
]
BIAS_HEADERS = [
    "data from",
    "analysed as",
    "seeds",
    "BRDF0 covered",
    "α covered",
    "TIS(70°) covered",
    "BRDF0 median / truth (mean)",
    "TIS(70°) median / truth (mean)",
]


@dataclass(frozen=True)
class NodeRow:
    instrument: str
    nodes: int
    build_seconds: float
    cubature_error: float
    raytrace_error: float
    raytrace_sigma: float
    gradient_microseconds: float

    @property
    def cells(self) -> list[str]:
        return [
            self.instrument,
            str(self.nodes),
            f"{self.build_seconds:.2f}",
            f"{100 * self.cubature_error:.3f}",
            f"{100 * self.raytrace_error:.3f}",
            f"{100 * self.raytrace_sigma:.3f}",
            f"{self.gradient_microseconds:.0f}",
        ]


def _gradient_microseconds(model) -> float:
    def total(vector):
        return jnp.sum(model.log_reflectance(Params(*vector)))

    function = jax.jit(jax.value_and_grad(total))
    x = jnp.asarray(np.array(UV_PAPER, float))
    jax.block_until_ready(function(x))
    repeats = 200
    started = time.perf_counter()
    for _ in range(repeats):
        jax.block_until_ready(function(x))
    return 1e6 * (time.perf_counter() - started) / repeats


def _full_cubature(scene: Scene, measurements, instrument: str, uniforms) -> list:
    full = []
    for index in range(len(measurements)):
        nodes = measurement_nodes(
            measurements.theta_i_deg[index],
            measurements.theta_s_deg[index],
            beam_geometry(scene, str(measurements.series[index])),
            uniforms,
        )
        weight = nodes.aperture_weight if instrument == "aperture" else nodes.image_weight
        full.append((nodes, weight))
    return full


def node_rows(scene: Scene, measurements, quick: bool, progress=print) -> list[NodeRow]:
    """Kernel accuracy and cost against the number of nodes per row."""
    from brdf_infer.studies.raytrace import raytrace_series

    rays = 2**17 if quick else 2**21
    progress(f"  ray tracer reference, {rays} rays per configuration")
    trace = raytrace_series(scene, measurements, UV_PAPER, rays=rays, seed=11)
    point = build_observation_model(scene, measurements)
    rows = [
        NodeRow(
            "point (Eq. 6)",
            1,
            0.0,
            float("nan"),
            float("nan"),
            float("nan"),
            _gradient_microseconds(point),
        )
    ]
    for instrument, value, error in (
        ("aperture", "simulated", "mc_se"),
        ("image", "image_ratio", "image_ratio_se"),
    ):
        reference = _full_reference(scene, measurements, instrument)
        for nodes in (16,) if quick else tuple(NODE_SHAPES):
            progress(f"  {instrument}: {nodes} nodes per row")
            ray_trace = (trace, value, error)
            rows.append(_node_row(scene, measurements, instrument, nodes, reference, ray_trace))
    return rows


def _full_reference(scene: Scene, measurements, instrument: str) -> dict[Params, np.ndarray]:
    """The raw reflectance of every row by the full cubature of ``instrument`` (all its
    candidate points), at ``UV_PAPER`` and at ``OTHER``."""
    uniforms = sobol_uniforms(DEFAULT_CANDIDATES[instrument])
    full = _full_cubature(scene, measurements, instrument, uniforms)
    return {
        params: np.array(
            [
                np.sum(
                    w
                    * np.exp(
                        log_brdf_hemisphere(n.theta_i_deg, n.theta_deg, n.phi_deg, params, False)
                    )
                )
                for n, w in full
            ]
        )
        for params in (UV_PAPER, OTHER)
    }


def _node_row(
    scene: Scene, measurements, instrument: str, nodes: int, reference: dict, ray_trace: tuple
) -> NodeRow:
    """The kernel of ``instrument`` compressed to ``nodes`` per row: its build time, its error
    against the full cubature (``reference``) and against the ray tracer (``ray_trace``: the
    series' trace, the name of its value and of that value's MC error), the cost of ln R and its
    gradient."""
    trace, value, error = ray_trace
    checked = check_instrument(scene, instrument)
    variant = replace(checked, instrument=replace(checked.instrument, nodes=nodes))
    clear_row_kernel_cache()  # time the build, not a cached kernel
    started = time.perf_counter()
    kernel = build_kernel(variant, measurements)
    build_seconds = time.perf_counter() - started
    cubature_error = 0.0
    for params, values in reference.items():
        predicted = np.exp(
            kernel_log_reflectance(
                lambda ti, t, p, q=params: log_brdf_hemisphere(ti, t, p, q, False),
                kernel,
            )
        )
        cubature_error = max(cubature_error, float(np.max(np.abs(predicted / values - 1))))
    model = build_observation_model(variant, measurements)
    predicted = np.exp(np.asarray(model.log_reflectance(UV_PAPER)))
    by_row = {
        (
            str(measurements.series[k]),
            measurements.theta_i_deg[k],
            measurements.theta_s_deg[k],
        ): predicted[k]
        for k in range(len(measurements))
    }
    traced = [
        (
            r[value],
            r[error],
            by_row[(scene.raytrace.series, r["theta_i_deg"], r["theta_s_deg"])],
        )
        for r in trace.rows
    ]
    return NodeRow(
        instrument,
        nodes,
        build_seconds,
        cubature_error,
        max(abs(k / v - 1) for v, _, k in traced),
        max(s / v for v, s, _ in traced),
        _gradient_microseconds(model),
    )


@dataclass(frozen=True)
class EssRow:
    instrument: str
    min_ess: float
    sampling_seconds: float
    divergences: int
    compile_seconds: float
    point_rate: float

    @property
    def cells(self) -> list[str]:
        rate = self.min_ess / self.sampling_seconds
        return [
            self.instrument,
            f"{self.min_ess:.0f}",
            f"{self.sampling_seconds:.1f}",
            f"{rate:.0f}",
            f"{rate / self.point_rate:.2f}",
            str(self.divergences),
            f"{self.compile_seconds:.1f}",
        ]


def ess_rows(scene: Scene, measurements, quick: bool, progress=print) -> list[EssRow]:
    """NUTS min-ESS (bulk, the six parameters) per second of sampling for each instrument."""
    from brdf_infer.posterior import build_posterior_model, run_nuts

    chains, warmup, draws = (2, 300, 300) if quick else (4, 1000, 1000)
    results = []
    for instrument in ("point", "aperture", "image"):
        progress(f"  NUTS with the '{instrument}' instrument, {chains} x ({warmup} + {draws})")
        model = build_posterior_model(check_instrument(scene, instrument), measurements)
        result = run_nuts(model, chains=chains, warmup=warmup, draws=draws, seed=5, progress=False)
        ess = az.ess({n: np.asarray(result.sites[n]) for n in PARAM_NAMES}, method="bulk")
        results.append(
            (
                instrument,
                float(min(float(ess[n]) for n in PARAM_NAMES)),
                result.seconds["sampling"],
                int(np.sum(result.stats["diverging"])),
                result.seconds["compile"],
            )
        )
    point_rate = results[0][1] / results[0][2]
    return [EssRow(*r, point_rate=point_rate) for r in results]


def bias_rows(scene: Scene, measurements, quick: bool, progress=print) -> tuple[list, list]:
    """The synthetic experiment (``brdf_infer.studies.instrument_bias``) with several seeds."""
    from brdf_infer.studies.instrument_bias import bias_experiment

    seeds = [0] if quick else list(range(6))
    rows, experiments = [], []
    for generated_by in ("aperture", "image"):
        progress(f"  data from the ray tracer's '{generated_by}' quantity, {len(seeds)} seeds")
        result = bias_experiment(
            scene,
            measurements,
            UV_PAPER,
            generated_by,
            seeds,
            chains=2,
            draws=500,
            warmup=500,
            rays=2**15 if quick else 2**18,
            progress=progress,
        )
        experiments.append(result)
        truth = result["truth"]
        for instrument in ("point", generated_by):
            fits = [f for f in result["fits"] if f["instrument"] == instrument]
            coverage = result["coverage"][instrument]
            rows.append(
                [
                    generated_by,
                    instrument,
                    str(len(fits)),
                    *(f"{coverage[q]:.2f}" for q in ("brdf0", "alpha", "tis_70deg")),
                    f"{np.mean([f['brdf0']['median'] for f in fits]) / truth['brdf0']:.3f}",
                    f"{np.mean([f['tis_70deg']['median'] for f in fits]) / truth['tis_70deg']:.3f}",
                ]
            )
    return rows, experiments
