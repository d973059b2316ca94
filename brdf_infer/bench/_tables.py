"""Markdown tables and fresh-process timings shared by the benchmark's sections."""

from __future__ import annotations

import json
import os
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
    environment = {**os.environ, "BRDF_INFER_CACHE": str(cache)}
    started = time.perf_counter()
    result = subprocess.run(
        [sys.executable, "-m", "brdf_infer", *argv, "--out", str(out), "--json"],
        capture_output=True,
        text=True,
        env=environment,
        check=True,
    )
    return time.perf_counter() - started, json.loads(result.stdout)
