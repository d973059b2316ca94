"""Benchmark of the persistent compilation cache: ``posterior`` and ``run`` of the bundled
scene in fresh processes, first with an empty cache folder (cold), then again (warm)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

HEADERS = [
    "command",
    "cold [s]",
    "warm [s]",
    "warm / cold",
    "compile cold → warm [s]",
    "programs compiled cold → warm",
    "loaded from the cache warm",
]


@dataclass(frozen=True)
class CacheRow:
    command: str
    cold: float
    warm: float
    compile_cold: float
    compile_warm: float
    compilations_cold: int
    compilations_warm: int
    hits_warm: int

    @property
    def cells(self) -> list[str]:
        return [
            f"`{self.command}`",
            f"{self.cold:.1f}",
            f"{self.warm:.1f}",
            f"{self.warm / self.cold:.2f}",
            f"{self.compile_cold:.1f} → {self.compile_warm:.1f}",
            f"{self.compilations_cold} → {self.compilations_warm}",
            str(self.hits_warm),
        ]


def _timed_process(argv: list[str], cache: Path) -> tuple[float, dict, int, int]:
    """Wall time, JSON output, XLA compilations and persistent-cache hits of one process
    (counted from JAX's compile log, ``JAX_LOG_COMPILES=1``)."""
    clock = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "brdf_infer", *argv, "--json"],
        capture_output=True,
        text=True,
        env=dict(os.environ, BRDF_INFER_CACHE=str(cache), JAX_LOG_COMPILES="1"),
    )
    seconds = time.perf_counter() - clock
    if done.returncode != 0:
        raise RuntimeError(done.stderr[-2000:])
    hits = done.stderr.lower().count("persistent compilation cache hit")
    compilations = done.stderr.count("Finished XLA compilation") - hits  # logged for hits too
    return seconds, json.loads(done.stdout), compilations, hits


def cache_rows(quick: bool, progress=print) -> list[CacheRow]:
    """Cold and warm wall time of ``posterior lya`` and ``run lya`` (each with its own empty
    cache folder); the NUTS compile time from the posterior summary. None with ``quick`` (a
    fresh process per row is the point, and it costs minutes)."""
    if quick:
        return []
    commands = [("posterior lya", ["posterior", "lya"]), ("run lya", ["run", "lya"])]
    rows = []
    with tempfile.TemporaryDirectory() as temporary:
        folder = Path(temporary)
        for k, (label, argv) in enumerate(commands):
            cache = folder / f"cache_{k}"
            timings = []
            for attempt in ("cold", "warm"):
                progress(f"  {label}, {attempt} cache")
                out = folder / f"out_{k}_{attempt}"
                seconds, payload, compilations, hits = _timed_process(
                    [*argv, "--out", str(out)], cache
                )
                summary = payload.get("posterior", payload)
                timings.append((seconds, summary["seconds"]["compile"], compilations, hits))
            (cold, compile_cold, count_cold, _), (warm, compile_warm, count_warm, hits) = timings
            rows.append(
                CacheRow(
                    label, cold, warm, compile_cold, compile_warm, count_cold, count_warm, hits
                )
            )
    return rows
