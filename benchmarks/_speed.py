"""The main job's cost where users feel it: ``run`` and ``posterior`` end to end in fresh
processes (cold: an empty compilation cache; warm: the same cache again), the posterior's
value-and-gradient inside a compiled loop, and the steps after sampling."""

from __future__ import annotations

import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks._tables import markdown_table, startup_seconds, timed_process
from brdf_infer.posterior import FlatPotential, build_model, build_posterior_model
from brdf_infer.scene import Scene

PROCESS_HEADERS = [
    "command",
    "cache",
    "wall, end to end [s]",
    "CPU user+sys [s]",
    "start-up: interpreter and imports [s]",
    "paper fit and least squares [s]",
    "compile and loading programs [s]",
    "sampling [s]",
    "records after sampling [s]",
    "report [s]",
    "scene, writing, exit [s]",
    "min bulk ESS",
    "divergences",
    "ESS per wall second",
]
GRADIENT_HEADERS = ["posterior model", "value and gradient in a compiled loop [µs]", "evaluations"]
STEP_HEADERS = ["step after sampling", "seconds"]
# what `posterior` imports before its own work (the start-up column)
STARTUP_MODULES = "brdf_infer.cli, brdf_infer.posterior"


@dataclass
class ProcessRow:
    """One command in a fresh process."""

    command: str
    cache: str
    wall: float
    summary: dict
    cpu: float = float("nan")  # user + sys of the process [s]
    startup: float = float("nan")  # interpreter and imports [s] (:func:`startup_seconds`)
    steps: dict | None = None  # a run's steps [s] (fits, posterior, studies, report)

    def cells(self) -> list[str]:
        seconds = self.summary["seconds"]
        ess = self.summary["diagnostics"]["ess_bulk_min"]
        # the run's "total" spans building the model to the summary; the rest of the wall
        # beyond the start-up is parsing, the scene, writing the files and exiting
        steps = self.steps or {}
        fits, report = steps.get("fits"), steps.get("report")
        rest = self.wall - self.startup - seconds["total"] - (fits or 0.0) - (report or 0.0)
        return [
            f"`brdf-infer {self.command}`",
            self.cache,
            f"{self.wall:.1f}",
            f"{self.cpu:.1f}",
            f"{self.startup:.1f}",
            "–" if fits is None else f"{fits:.1f}",
            f"{seconds['compile']:.1f}",
            f"{seconds['sampling']:.1f}",
            f"{sum(seconds['after_sampling'].values()):.2f}",
            "–" if report is None else f"{report:.1f}",
            f"{rest:.1f}",
            f"{ess:.0f}",
            str(self.summary["diagnostics"]["divergences"]),
            f"{ess / self.wall:.0f}",
        ]


def process_rows(scene_name: str = "lya", progress=print) -> list[ProcessRow]:
    """``posterior`` and ``run`` of the scene, each cold (its own empty cache) then warm."""
    rows = []
    startup = startup_seconds(STARTUP_MODULES)
    with tempfile.TemporaryDirectory() as folder:
        base = Path(folder)
        for command in ("posterior", "run"):
            cache = base / f"cache-{command}"
            for state in ("cold", "warm"):
                progress(f"  {command} {scene_name}, {state} cache ...")
                out = base / f"{command}-{state}"
                wall, cpu, payload = timed_process([command, scene_name], cache, out)
                summary = payload if command == "posterior" else payload["posterior"]
                steps = None if command == "posterior" else payload.get("step_seconds")
                name = f"{command} {scene_name}"
                rows.append(ProcessRow(name, state, wall, summary, cpu, startup, steps))
    return rows


def after_sampling_rows(rows: list[ProcessRow]) -> list[list[str]]:
    """The warm ``posterior`` run's steps after sampling, one row each."""
    warm = next(r for r in rows if r.command.startswith("posterior") and r.cache == "warm")
    steps = warm.summary["seconds"]["after_sampling"]
    return [[name, f"{seconds:.2f}"] for name, seconds in steps.items()]


def gradient_microseconds(flat: FlatPotential, data, evaluations: int = 4000) -> float:
    """Mean wall time of one value-and-gradient of the potential inside a compiled loop
    (best of 5 repetitions, compilation excluded)."""
    value_and_grad = jax.value_and_grad(flat.potential)

    def loop(z, data):
        def body(i, total):
            value, gradient = value_and_grad(z + 1e-9 * i, data)
            return total + value + gradient.sum()

        return jax.lax.fori_loop(0, evaluations, body, 0.0)

    compiled = jax.jit(loop).lower(jnp.zeros(flat.dimension), data).compile()
    start = jnp.full(flat.dimension, 0.1)
    jax.block_until_ready(compiled(start, data))
    best = np.inf
    for _ in range(5):
        clock = time.perf_counter()
        jax.block_until_ready(compiled(start, data))
        best = min(best, time.perf_counter() - clock)
    return 1e6 * best / evaluations


def gradient_rows(scene: Scene, measurements) -> list[list[str]]:
    """Value and gradient of the whitened (sampled) and the plain posterior model."""
    rows = []
    for label, model in (
        ("whitened (what NUTS samples)", build_model(scene, measurements)),
        ("not whitened", build_posterior_model(scene, measurements, reparametrise=False)),
    ):
        flat = FlatPotential(model)
        rows.append([label, f"{gradient_microseconds(flat, model.data):.1f}", "4000 x 5"])
    return rows


def write_speed_report(out: Path, quick: bool, progress=print) -> Path:
    """``brdf-infer bench --speed``: the main job's cost, the peers on the same posterior,
    the concurrency stress test and a batch of unequal scenes, measured in one run."""
    from benchmarks._peers_section import peer_section
    from benchmarks._timing import machine_description
    from brdf_infer._internal.atomic import atomic_write_bytes
    from brdf_infer.scene import load_scene

    started = time.perf_counter()
    load_before = os.getloadavg()[0]  # other jobs on the cores lengthen every wall time
    scene = load_scene("lya")
    measurements = scene.load_measurements()
    progress("speed 1/3: value and gradient ...")
    gradients = gradient_rows(scene, measurements)
    progress("speed 2/3: the main job in fresh processes ...")
    processes = process_rows("lya", progress)
    progress("speed 3/3: peers ...")
    peers = peer_section(quick, progress)
    sections = [
        "# Benchmarks: the main job's speed",
        "",
        f"Machine: {machine_description()}.  ",
        f"Mode: {'quick' if quick else 'full'}; total wall time "
        f"{time.perf_counter() - started:.0f} s; 1-minute load average "
        f"{load_before:.1f} at the start, {os.getloadavg()[0]:.1f} at the end.  ",
        "Regenerate: `brdf-infer bench --speed`. Every row was measured in this one run.",
        "",
        "## The main job, end to end",
        "",
        "Fresh processes (`python -m brdf_infer COMMAND lya --json`), wall time from start to "
        "exit. Cold: an empty compilation cache folder; warm: the same folder again. NUTS: "
        "4 chains × (1000 warmup + 1000 draws), side by side in threads (one per core). "
        "`run` is the scene's one posterior with the paper fit, least squares and the report "
        "(no `[studies]` in the bundled scene). ESS per wall second divides the smallest bulk "
        "ESS by the whole wall time. The wall splits into the start-up (a fresh interpreter "
        "importing the CLI and the posterior, best of 3), `run`'s paper fit and least "
        "squares, the sampler's compile (warm: loading its stored traced programs, "
        "`programs/` of the cache, and their compiled form from XLA's cache), sampling, the "
        "records after sampling (next table), `run`'s report, and the rest: parsing, loading "
        "the scene and building the model, writing the files, exiting.",
        "",
        markdown_table(PROCESS_HEADERS, [row.cells() for row in processes]),
        "",
        "## After sampling (warm `posterior`)",
        "",
        markdown_table(STEP_HEADERS, after_sampling_rows(processes)),
        "",
        "## The posterior's value and gradient",
        "",
        "One value-and-gradient of the potential (42 rows, covariance D + W Wᵀ with 12 "
        "columns) inside a compiled `fori_loop`, best of 5 repetitions, compile time "
        "excluded. The whitened model solves its linear regression at every evaluation "
        "(brdf_infer._internal.lowrank: no LAPACK calls).",
        "",
        markdown_table(GRADIENT_HEADERS, gradients),
        "",
        peers,
    ]
    atomic_write_bytes(out, "\n".join(sections).encode())
    return out


def write_stress_report(out: Path, quick: bool, progress=print) -> Path:
    """``brdf-infer bench --stress``: every concurrent path 20 times (``quick``: 2) under the
    watchdog. Timing does not matter here, only hangs: it may run beside other work."""
    from benchmarks._stress import HEADERS as STRESS_HEADERS
    from benchmarks._stress import StressSettings, stress_rows
    from benchmarks._timing import machine_description
    from brdf_infer._internal.atomic import atomic_write_bytes

    started = time.perf_counter()
    stress = stress_rows(2 if quick else 20, progress=progress)
    sections = [
        "# Benchmarks: concurrency under a watchdog",
        "",
        f"Machine: {machine_description()}.  ",
        f"Mode: {'quick' if quick else 'full'}; total wall time "
        f"{time.perf_counter() - started:.0f} s.  ",
        "Regenerate: `brdf-infer bench --stress`.",
        "",
        "Each path runs in a fresh process with a compilation cache folder of its own (the "
        "first repetition compiles), under a watchdog that reads the stacks and kills the "
        "process group of a repetition that outlives its timeout "
        f"({StressSettings().timeout:.0f} s): `batch` in threads mode over "
        f"{StressSettings().scenes} scenes, `batch --mode vmap` over two forced CPU devices, "
        "`posterior lya` (chains side by side), and two Python threads executing the "
        "posterior's compiled, vmapped constraining map and potential "
        f"{StressSettings().calls} times each, and {StressSettings().processes} processes of "
        "`fit lya --method lsq` started at once on one fresh cache folder (a new folder every "
        "repetition, at most 5: each compiles cold four times over; they must all finish "
        "with the same result) (benchmarks._stress). Before the "
        "posterior's linear algebra left LAPACK, both batch paths and the two threads hung "
        "(jaxlib 0.10.2's LAPACK handlers wait on the intra-op pool from a pool thread); "
        "the posterior, then sequential, did not.",
        "",
        markdown_table(STRESS_HEADERS, [row.cells for row in stress]),
        "",
    ]
    atomic_write_bytes(out, "\n".join(sections).encode())
    return out
