"""Reproduce the open memory defect: resident memory grows while NUTS chains of a large table
sample side by side in threads.

    python tools/nuts_memory_growth.py [--radial 3] [--workers 2] [--seconds 120]

Builds the benchmark's full-grid table (:mod:`brdf_infer.bench._cost_curve`), thinned by
``--radial`` (3: 19 637 rows), and runs two chains through :class:`NutsProgram` with
``--workers`` threads, printing the resident memory every 10 s. Measured 2026-11-27 on 2
cores: two workers grow 18–40 MB/s (faster with ``MALLOC_ARENA_MAX=1``; also with one compiled
executable per thread), one worker stays flat (737 MB); two threads running a compiled
value-and-gradient loop of the same potential stay flat. Fixed when two workers stay flat.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import threading
import time
from pathlib import Path

import jax

from brdf_infer.bench._cost_curve import scene_file, write_table
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
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        table = write_table(Path(folder))
        scene = load_scene(scene_file(Path(folder), table, args.radial, 1))
        model = build_model(scene, scene.load_measurements())
        program = NutsProgram(model, warmup=100)
        keys = jax.random.split(jax.random.PRNGKey(0), 2)
        started = time.perf_counter()
        stop = threading.Event()
        worker = threading.Thread(
            target=lambda: program.run(model.data, keys, 150, workers=args.workers, cancel=stop),
            daemon=True,
        )
        worker.start()
        while worker.is_alive() and time.perf_counter() - started < args.seconds:
            elapsed = time.perf_counter() - started
            print(f"t = {elapsed:4.0f} s: {resident_mb():6.0f} MB", flush=True)
            time.sleep(10)
        stop.set()
    os._exit(0)  # a chain mid-chunk would hold the interpreter's exit until it ends


if __name__ == "__main__":
    main()
