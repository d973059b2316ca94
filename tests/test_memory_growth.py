"""Memory stays flat: while two NUTS chains of a large table sample in threads, and over
runs repeated in one process.

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


RUNS_TOOL = Path(__file__).resolve().parents[1] / "tools" / "repeated_runs_memory.py"
PEAK_GROWTH = 0.15  # the peak from the third run on may grow by this share of the third's


@pytest.mark.slow  # about 3 minutes on 2 cores: eight runs of the main job
def test_the_main_job_repeated_in_one_process_holds_its_memory(tmp_path):
    """The README's Python example (``workflow.run`` on ``lya``) eight times in one process:
    the peak memory after the eighth run is within 15 % of the peak after the third (the
    first two compile and fill the caches). The compiled programs live on the model and
    family objects of a run, not in module-level caches keyed by identity, which held every
    run's model and data."""
    result = subprocess.run(
        [sys.executable, str(RUNS_TOOL), "--runs", "8", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=1500,
        check=True,
    )
    peaks = [float(mb) for mb in re.findall(r"run \d+: (\d+) MB peak", result.stdout)]
    assert len(peaks) == 8, result.stdout
    assert peaks[-1] <= (1 + PEAK_GROWTH) * peaks[2], result.stdout
