"""Resident memory while NUTS chains of a large table sample side by side in threads.

    python tools/nuts_memory_growth.py [--radial 3] [--workers 2] [--seconds 120] [--ynn]

Builds the benchmark's full-grid table (:mod:`benchmarks._cost_curve`), thinned by
``--radial`` (3: 19 637 rows), and runs two chains through :class:`NutsProgram` with
``--workers`` threads, printing the resident memory every 10 s. Measured 2026-11-27 on 2
cores: two workers grow 18–40 MB/s (faster with ``MALLOC_ARENA_MAX=1``; also with one compiled
executable per thread), one worker stays flat (737 MB); two threads running a compiled
value-and-gradient loop of the same potential stay flat.

Cause (found with memray's native stacks): XLA's CPU backend in jaxlib 0.10 runs large fused
loops through YNNPACK (``YnnFusionThunk``); when two threads run the same program at once, the
memory allocated under its pooled executables grows without bound (also with jemalloc, so not
the allocator). :class:`NutsProgram` compiles with that fusion off
(``CPU_COMPILER_OPTIONS``); measured: two workers flat at 1.46 GB for 60 s. ``--ynn`` compiles
with XLA's default instead (the planted fault: grows again). A 42-row table does not grow either
way. ``tests/test_memory_growth.py`` (slow) runs this script both ways.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

import jax

import brdf_infer

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the checkout: benchmarks/
from benchmarks._cost_curve import scene_file, write_table
from brdf_infer.posterior import _nuts as nuts
from brdf_infer.posterior import build_model
from brdf_infer.posterior._nuts import NutsProgram
from brdf_infer.scene import load_scene


def resident_mb() -> float:
    with open("/proc/self/statm", encoding="ascii") as handle:
        return int(handle.read().split()[1]) * 4096 / 2**20


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--radial", type=int, default=3)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seconds", type=float, default=120.0)
    parser.add_argument("--ynn", action="store_true", help="XLA's default fusion (the fault)")
    args = parser.parse_args()
    if args.ynn:
        nuts.CPU_COMPILER_OPTIONS = {}
    brdf_infer.use_float64()
    with tempfile.TemporaryDirectory() as folder:
        table = write_table(Path(folder))
        scene = load_scene(scene_file(Path(folder), table, args.radial, 1))
        model = build_model(scene, scene.load_measurements())
        program = NutsProgram(model, warmup=100, warmup_tree_depth=4)  # chunks of seconds
        keys = jax.random.split(jax.random.PRNGKey(0), 2)
        iterations = [0]
        started = time.perf_counter()
        stop = threading.Event()
        worker = threading.Thread(
            target=lambda: program._single(  # chains that outlast the measurement
                model.data,
                keys,
                10**6,
                on_chunk=lambda n: iterations.__setitem__(0, iterations[0] + n),
                workers=args.workers,
                cancel=stop,
            ),
            daemon=True,
        )
        worker.start()
        while worker.is_alive() and time.perf_counter() - started < args.seconds:
            elapsed = time.perf_counter() - started
            print(f"t = {elapsed:4.0f} s: {resident_mb():6.0f} MB, {iterations[0]} its", flush=True)
            time.sleep(10)
        stop.set()
    os._exit(0)  # a chain mid-chunk would hold the interpreter's exit until it ends


if __name__ == "__main__":
    main()
