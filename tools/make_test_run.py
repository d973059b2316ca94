"""Write the small run folder the fast test tier reads (tests/data/lya_run).

The readers of a finished run (``report``, ``tis --run``, ``export --run``, ``design``) are
tested in the fast tier on this committed folder instead of a NUTS run made in the test
session: the bundled ``lya`` scene's posterior from 2 chains of 150 draws after 150 warmup
iterations, without the width's refits, and no report (the readers write it). Its numbers
are not the bundled scene's answer (too few draws; its verdict is not green): it is a run
folder of the current format. A full-tier test (tests/test_committed_run.py) compares its
files' fields with a fresh run's and asks for this script when they differ.

    .venv/bin/python tools/make_test_run.py
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import brdf_infer  # noqa: E402
from brdf_infer.posterior import run_posterior  # noqa: E402
from brdf_infer.scene import load_scene  # noqa: E402

TARGET = REPO / "tests" / "data" / "lya_run"
SMALL_NUTS = {"chains": 2, "warmup": 150, "draws": 150, "seed": 0}


def write_small_run(out: Path) -> None:
    """The small run of the bundled scene (``SMALL_NUTS``), its width without refits."""
    scene = load_scene("lya")
    run_posterior(
        scene, scene.load_measurements(), out=out, progress=False, refit=False, **SMALL_NUTS
    )


def main() -> None:
    brdf_infer.use_float64()
    with tempfile.TemporaryDirectory() as scratch:
        written = Path(scratch) / "lya_run"
        write_small_run(written)
        shutil.rmtree(TARGET, ignore_errors=True)
        shutil.copytree(written, TARGET)
    names = ", ".join(sorted(path.name for path in TARGET.iterdir()))
    print(f"wrote {TARGET.relative_to(REPO)}: {names}")


if __name__ == "__main__":
    main()
