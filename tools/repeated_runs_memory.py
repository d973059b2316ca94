"""Peak and resident memory of the README's Python example run N times in one process.

Prints one line per run: ``run K: peak MB, resident MB, seconds``. tests/test_memory_growth.py
(slow) runs it and checks that the peak holds from the third run on. Usage:
``python tools/repeated_runs_memory.py --runs 8 --out DIR``.
"""

from __future__ import annotations

import argparse
import resource
import tempfile
import time
from pathlib import Path


def resident_mb() -> float:
    """This process's resident memory now [MB] (Linux's /proc)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--runs", type=int, default=8)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp())

    import brdf_infer
    from brdf_infer.scene import load_scene
    from brdf_infer.workflow import run

    brdf_infer.use_float64()
    for k in range(1, args.runs + 1):
        started = time.perf_counter()
        scene = load_scene("lya")
        result = run(scene, scene.load_measurements(), out / f"lya-{k}")
        assert result.verdict.text
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        seconds = time.perf_counter() - started
        print(f"run {k}: {peak:.0f} MB peak, {resident_mb():.0f} MB resident, {seconds:.1f} s")


if __name__ == "__main__":
    main()
