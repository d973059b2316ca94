"""Benchmark of ``brdf-infer batch``: wall time per scene of one batch of N synthetic scenes
(the bundled geometry, every reflectance scaled by its own factor) against separate
``brdf-infer posterior`` processes, on the same machine in one run."""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from brdf_infer.scene import Scene
from brdf_infer.workflow.batch import BatchSettings, run_batch

HEADERS = [
    "scenes",
    "batch wall [s]",
    "batch per scene [s]",
    "of which compile [s]",
    "separate posterior per scene [s]",
    "batch / separate",
]


@dataclass(frozen=True)
class BatchRow:
    scenes: int
    seconds: float
    compile_seconds: float
    separate_per_scene: float

    @property
    def cells(self) -> list[str]:
        per_scene = self.seconds / self.scenes
        return [
            str(self.scenes),
            f"{self.seconds:.1f}",
            f"{per_scene:.1f}",
            f"{self.compile_seconds:.1f}",
            f"{self.separate_per_scene:.1f}",
            f"{per_scene / self.separate_per_scene:.2f}",
        ]


def synthetic_scenes(scene: Scene, count: int, folder: Path) -> list[str]:
    """``count`` copies of ``scene`` (its model structure, so its compiled programs), each of
    its rows with the reflectances (and their σ) scaled by 0.7, 0.8, …"""
    lines = scene.measurements_path.read_text().splitlines()
    header = lines[0].split(",")
    columns = [header.index("reflectance"), header.index("reflectance_err")]
    paths = []
    for k in range(count):
        factor = 0.7 + 0.05 * (k % 13)
        rows = [lines[0]]
        for line in lines[1:]:
            cells = line.split(",")
            for c in columns:
                if cells[c]:
                    cells[c] = f"{float(cells[c]) * factor:.6e}"
            rows.append(",".join(cells))
        csv = folder / f"rows_{k}.csv"
        csv.write_text("\n".join(rows) + "\n")
        path = folder / f"scene_{k}.toml"
        path.write_text(scene_text_with_measurements(scene, csv, f"s{k}"))
        paths.append(str(path))
    return paths


def scene_text_with_measurements(scene: Scene, measurements: Path, name: str) -> str:
    """``scene``'s TOML text named ``name`` and measuring ``measurements``: the same model
    structure, so the same compiled programs. The files it names become absolute paths, so
    the text may be written anywhere."""
    text = scene.path.read_text()
    text = text.replace(f'name = "{scene.name}"', f'name = "{name}"', 1)
    text = text.replace(
        f'"{scene.measurements_path.name}"', f'"{measurements.resolve().as_posix()}"', 1
    )
    reference = scene.outputs.tis_reference
    if reference is not None:
        text = text.replace(f'"{reference.name}"', f'"{reference.resolve().as_posix()}"', 1)
    return text


def _separate_run(path: str, out: Path) -> float:
    clock = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "brdf_infer", "posterior", path, "--out", str(out), "--json"],
        capture_output=True,
        text=True,
    )
    if done.returncode != 0:
        raise RuntimeError(done.stderr[-2000:])
    return time.perf_counter() - clock


def batch_rows(scene: Scene, quick: bool, progress=print) -> list[BatchRow]:
    """Batches of 1 and 8 scenes (default NUTS settings) against two separate ``posterior``
    processes (persistent compilation cache warm, as after a first run); ``quick``: 1 and 2
    scenes with short chains, no separate runs."""
    counts = (1, 2) if quick else (1, 8)
    settings = BatchSettings(chains=2, draws=200, warmup=200) if quick else BatchSettings()
    rows = []
    with tempfile.TemporaryDirectory() as temporary:
        folder = Path(temporary)
        paths = synthetic_scenes(scene, max(counts), folder)
        separate = []
        if not quick:
            for k in range(3):  # the first warms the persistent compilation cache
                progress(f"  separate posterior {k + 1} of 3")
                separate.append(_separate_run(paths[k], folder / f"separate_{k}"))
        per_scene = min(separate[1:]) if separate else float("nan")
        for count in counts:
            progress(f"  batch of {count} scene(s)")
            result = run_batch(paths[:count], folder / f"batch_{count}", settings)
            rows.append(BatchRow(count, result.seconds, result.compile_seconds, per_scene))
    return rows
