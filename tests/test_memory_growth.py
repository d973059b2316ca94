"""Resident memory stays flat while two NUTS chains of a large table sample in threads.

XLA's CPU backend (jaxlib 0.10) grows without bound when two threads run one program whose
large loops it hands to YNNPACK; :class:`brdf_infer.posterior._nuts.NutsProgram` compiles with
that fusion off. ``tools/nuts_memory_growth.py`` prints the resident memory every 10 s; the
planted fault (``--ynn``, XLA's default) must grow. Slow: about 8 minutes on 2 cores.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import jax
import pytest

from brdf_infer.posterior._nuts import _compiler_options

TOOL = Path(__file__).resolve().parents[1] / "tools" / "nuts_memory_growth.py"
SECONDS = 220
SETTLED_ITERATIONS = 100  # both chains a chunk in: every program compiled and run
MEASURED_S = 60  # the growth is read over at least this long after that
FLAT_MB = 40.0  # flat; the fault grows 18-40 MB/s on a quiet machine


def growth_mb(*options: str) -> float:
    """Resident memory gained [MB] from the first reading with :data:`SETTLED_ITERATIONS`
    iterations done (both chains together) to the last, at least :data:`MEASURED_S` later."""
    result = subprocess.run(
        [sys.executable, str(TOOL), "--seconds", str(SECONDS), *options],
        capture_output=True,
        text=True,
        timeout=SECONDS + 240,
        check=True,
    )
    readings = [
        (float(t), float(mb), int(its))
        for t, mb, its in re.findall(r"t =\s*(\d+) s:\s*(\d+) MB, (\d+) its", result.stdout)
    ]
    settled = [(t, mb) for t, mb, its in readings if its >= SETTLED_ITERATIONS]
    assert settled and settled[-1][0] - settled[0][0] >= MEASURED_S, result.stdout
    return settled[-1][1] - settled[0][1]


@pytest.mark.slow
def test_two_chain_threads_hold_their_memory():
    assert growth_mb() < FLAT_MB


@pytest.mark.slow
@pytest.mark.skipif(
    jax.default_backend() != "cpu" or _compiler_options() is None,
    reason="the fault is XLA's CPU YNNPACK fusion, in the jaxlib that knows the option",
)
def test_planted_fault_grows():
    assert growth_mb("--ynn") > 4 * FLAT_MB
