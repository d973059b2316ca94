"""Markdown tables and fresh-process timings shared by the benchmark's sections."""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path


def markdown_table(headers: list[str], rows: list[list[str]]) -> str:
    """A GitHub-flavoured Markdown table."""
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def timed_command(argv: list[str], cache: Path, out: Path) -> tuple[float, dict]:
    """Wall time [s] of ``brdf-infer ARGV --out OUT --json`` in a fresh process with the
    compilation cache in ``cache``, and its JSON."""
    wall, _, payload = timed_process(argv, cache, out)
    return wall, payload


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def timed_process(argv: list[str], cache: Path, out: Path) -> tuple[float, float, dict]:
    """:func:`timed_command` with the process's CPU time: (wall [s], user + sys CPU [s],
    JSON)."""
    environment = {**os.environ, "BRDF_INFER_CACHE": str(cache)}
    cpu, started = _children_cpu(), time.perf_counter()
    result = subprocess.run(
        [sys.executable, "-m", "brdf_infer", *argv, "--out", str(out), "--json"],
        capture_output=True,
        text=True,
        env=environment,
        check=True,
    )
    wall = time.perf_counter() - started
    return wall, _children_cpu() - cpu, json.loads(result.stdout)


def startup_seconds(modules: str, repeats: int = 3) -> float:
    """Best wall time [s] of a fresh interpreter that imports ``modules`` (comma separated)
    and exits: a command's start-up before its own work."""
    best = float("inf")
    for _ in range(repeats):
        started = time.perf_counter()
        subprocess.run([sys.executable, "-c", f"import {modules}"], check=True)
        best = min(best, time.perf_counter() - started)
    return best
