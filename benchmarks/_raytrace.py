"""Ray tracer benchmark: Monte Carlo error against rays and run time for both estimators."""

from __future__ import annotations

import time
from dataclasses import dataclass

import jax

from brdf_infer.model.params import UV_PAPER
from brdf_infer.scene import Scene
from brdf_infer.studies.raytrace import (
    CHUNK_RAYS,
    build_setup,
    compile_tallies,
    configurations,
    trace_configuration,
)

BENCH_CONFIGURATIONS = ((45.0, 0.0), (80.0, 5.0))  # a flat BRDF, and the steepest grazing case
REFERENCE_RAYS = 2**22


@dataclass(frozen=True)
class RaytraceRow:
    configuration: str
    estimator: str
    rays: int
    relative_se: float  # the estimator's own MC standard error / value
    relative_error: float  # |value − long NEE reference| / reference
    seconds: float
    compile_seconds: float

    @property
    def rays_per_second(self) -> float:
        return self.rays / self.seconds


def raytrace_rows(scene: Scene, quick: bool) -> tuple[list[RaytraceRow], int]:
    """Rows for both estimators at increasing ray counts; returns them and the reference rays."""
    setup, limiting = build_setup(scene)
    constants = scene.model.constants
    measured = configurations(scene, scene.load_measurements())
    ray_counts = [2**14, 2**16, 2**18] + ([] if quick else [2**20, 2**22])
    reference_rays = REFERENCE_RAYS // (16 if quick else 1)
    rows = []
    for theta_i, delta in BENCH_CONFIGURATIONS:
        configuration = next(
            c for c in measured if (c.theta_i_deg, c.delta_deg) == (theta_i, delta)
        )
        reference = trace_configuration(
            configuration,
            UV_PAPER,
            setup,
            limiting,
            constants,
            reference_rays,
            jax.random.PRNGKey(999),
        ).simulated
        for estimator in ("nee", "naive"):
            for rays in ray_counts:
                compile_seconds = compile_tallies(
                    UV_PAPER, setup, constants, min(rays, CHUNK_RAYS), estimator, limiting, False
                )
                started = time.perf_counter()
                estimate = trace_configuration(
                    configuration,
                    UV_PAPER,
                    setup,
                    limiting,
                    constants,
                    rays,
                    jax.random.PRNGKey(rays),
                    estimator,
                )
                seconds = time.perf_counter() - started
                rows.append(
                    RaytraceRow(
                        f"θi = {theta_i:g}°, δ = {delta:+g}°",
                        estimator,
                        rays,
                        estimate.mc_se / estimate.simulated if estimate.simulated else float("inf"),
                        abs(estimate.simulated - reference) / reference,
                        seconds,
                        compile_seconds,
                    )
                )
    return rows, reference_rays
