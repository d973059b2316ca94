"""The benchmark's cost curve: what a run costs as the rows grow from the bundled 42 to a
whole imaging-scatterometer table (issue 35).

The tables are one full-grid ``.BSDF`` export of the parameter set ``uv-paper`` (18 angles of
incidence 0–85°, azimuth step 5°, radial step 1°: 37 × 176 × 18 cells, 59 585 of them above
the horizon and positive), each value multiplied by exp(0.05 ε), ε ~ N(0, 1), and read
through the scene's ``[bsdf]`` thinning for the smaller sizes. Each size runs ``brdf-infer
posterior`` and ``brdf-infer report`` in fresh processes sharing one compilation cache, at
fixed reduced NUTS settings, so that the columns grow with the rows alone (the run's own
``compile`` seconds are apart from its sampling); the value-and-gradient time is measured in
this process. The full grid is measured for its value and gradient only: its sampling at
these settings would take longer than the whole benchmark on 2 cores, and the table says
what the gradient projects.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from brdf_infer.bench._tables import markdown_table
from brdf_infer.runs.folder import RunFolder

SCATTER = 0.05  # lognormal 1σ of the synthetic table's values
CHAINS, WARMUP, DRAWS = 2, 200, 200  # the curve's reduced NUTS settings
SIZES = (  # label, [bsdf] keep_every_radial, keep_every_azimuth (None: the bundled scene)
    ("bundled", None, None),
    ("2 × 10³", 10, 3),
    ("2 × 10⁴", 3, 1),
)
FULL_GRID = ("6 × 10⁴ (full grid)", 1, 1)  # value and gradient only (module docstring)
HEADERS = [
    "table",
    "rows",
    "value and gradient [µs]",
    "[µs / row]",
    "posterior wall [s]",
    "of it compiling [s]",
    "sampling [s]",
    "after sampling [s]",
    "report [s]",
    "peak memory [GiB]",
    "posterior.nc [MB]",
]


@dataclass(frozen=True)
class CostRow:
    """One size of the curve (units in :data:`HEADERS`)."""

    label: str
    rows: int
    gradient_us: float
    posterior_s: float
    compile_s: float
    sampling_s: float
    after_sampling_s: float
    report_s: float
    peak_gib: float
    netcdf_mb: float

    def cells(self) -> list[str]:
        return [
            self.label,
            f"{self.rows}",
            f"{self.gradient_us:.0f}",
            f"{self.gradient_us / self.rows:.2f}",
            f"{self.posterior_s:.1f}",
            f"{self.compile_s:.1f}",
            f"{self.sampling_s:.1f}",
            f"{self.after_sampling_s:.1f}",
            f"{self.report_s:.1f}",
            f"{self.peak_gib:.2f}",
            f"{self.netcdf_mb:.1f}",
        ]


def write_table(folder: Path, seed: int = 0) -> Path:
    """The full-grid table (module docstring) in ``folder``; its path."""
    subprocess.run(
        [
            *(sys.executable, "-m", "brdf_infer", "export", "--params", "uv-paper"),
            *("--out", str(folder / "export"), "--azimuth-step", "5", "--radial-step", "1"),
        ],
        check=True,
        capture_output=True,
    )
    rng = np.random.default_rng(seed)
    lines, inside = [], False
    for line in (folder / "export" / "params.bsdf").read_text().splitlines():
        if line.startswith(("DataBegin", "DataEnd")):
            inside = line.startswith("DataBegin")
        elif inside and line[:1].isdigit():
            values = np.asarray(line.split(), float)
            values *= np.exp(SCATTER * rng.standard_normal(values.size))
            line = "\t".join(f"{v:.6e}" for v in values)
        lines.append(line)
    path = folder / "table.bsdf"
    path.write_text("\n".join(lines) + "\n")
    return path


def scene_file(folder: Path, table: Path, radial: int, azimuth: int) -> Path:
    """A scene reading ``table`` with the given thinning."""
    path = folder / f"table_{radial}_{azimuth}.toml"
    path.write_text(
        f'name = "table-{radial}-{azimuth}"\nmeasurements = "{table.name}"\n'
        f"[errors]\nreflectance_rel = {SCATTER}\n"
        f"[bsdf]\nkeep_every_radial = {radial}\nkeep_every_azimuth = {azimuth}\n"
    )
    return path


def measured_process(argv: list[str], cache: Path) -> tuple[float, float, str]:
    """(wall [s], peak resident memory [GiB], stdout) of ``brdf-infer ARGV`` in a fresh
    process with the compilation cache in ``cache``."""
    environment = {**os.environ, "BRDF_INFER_CACHE": str(cache)}
    started = time.perf_counter()
    process = subprocess.Popen(
        [sys.executable, "-m", "brdf_infer", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        env=environment,
        text=True,
    )
    output = process.stdout.read() if process.stdout else ""
    _, status, usage = os.wait4(process.pid, 0)
    process.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - started
    if process.returncode != 0:
        raise RuntimeError(f"brdf-infer {' '.join(argv)} exited {process.returncode}")
    return wall, usage.ru_maxrss * 1024 / 2**30, output


def cost_row(label: str, scene: str, scratch: Path, cache: Path) -> CostRow:
    """One size: the gradient here, then ``posterior`` and ``report`` in fresh processes."""
    import json

    rows, gradient = scene_gradient(scene)
    out = scratch / f"run-{rows}"
    argv = ["posterior", scene, "--chains", str(CHAINS), "--warmup", str(WARMUP)]
    argv += ["--draws", str(DRAWS), "--out", str(out), "--json"]
    wall, peak, output = measured_process(argv, cache)
    seconds = json.loads(output)["seconds"]
    report_wall, report_peak, _ = measured_process(["report", str(out)], cache)
    return CostRow(
        label=label,
        rows=rows,
        gradient_us=gradient,
        posterior_s=wall,
        compile_s=float(seconds.get("compile", 0.0)),
        sampling_s=float(seconds["sampling"]),
        after_sampling_s=float(sum(seconds["after_sampling"].values())),
        report_s=report_wall,
        peak_gib=max(peak, report_peak),
        netcdf_mb=RunFolder(out).posterior_file.stat().st_size / 1e6,
    )


def scene_gradient(scene: str, evaluations: int | None = None) -> tuple[int, float]:
    """(rows, value-and-gradient [µs]) of a scene's whitened potential, averaged over
    ``evaluations`` in a compiled loop (default: 4 × 10⁶ row-evaluations, 20 to 4000)."""
    from brdf_infer.bench._speed import gradient_microseconds
    from brdf_infer.posterior import FlatPotential, build_model
    from brdf_infer.scene import load_scene

    loaded = load_scene(scene)
    rows = loaded.load_measurements()
    model = build_model(loaded, rows)
    if evaluations is None:
        evaluations = int(max(20, min(4000, 4e6 // len(rows))))
    return len(rows), gradient_microseconds(FlatPotential(model), model.data, evaluations)


def cost_rows(quick: bool, progress=print) -> tuple[list[CostRow], tuple[int, float] | None]:
    """The curve (module docstring) and the full grid's (rows, gradient µs); ``quick``: the
    two smallest sizes only, no full grid."""
    rows = []
    with tempfile.TemporaryDirectory() as scratch_name:
        scratch = Path(scratch_name)
        table = write_table(scratch)
        for label, radial, azimuth in SIZES[: 2 if quick else None]:
            scene = "lya" if radial is None else str(scene_file(scratch, table, radial, azimuth))
            progress(f"cost curve: {label} ...")
            rows.append(cost_row(label, scene, scratch, scratch / "cache"))
        full = None
        if not quick:
            progress(f"cost curve: {FULL_GRID[0]}, value and gradient ...")
            full = scene_gradient(str(scene_file(scratch, table, *FULL_GRID[1:])), 20)
    return rows, full


def cost_section(rows: list[CostRow], full: tuple[int, float] | None) -> list[str]:
    """The report's section of the curve and the full grid's projection."""
    projection = []
    if full is not None and len(rows) > 1:
        largest = rows[-1]
        sampling = largest.sampling_s * full[1] / largest.gradient_us
        projection = [
            f"The full grid, {full[0]} rows: value and gradient {full[1]:.0f} µs "
            f"({full[1] / full[0]:.2f} µs a row); at the sampling settings above its NUTS "
            f"run would take about {sampling:.0f} s (the {largest.rows}-row sampling scaled "
            "by the gradients' ratio, the same number of gradients assumed), and at the "
            f"defaults (4 chains × 2000 iterations) about {10 * sampling:.0f} s.",
            "",
        ]
    return [
        "## Cost against the number of rows",
        "",
        f"Whole instrument tables: a full-grid `.BSDF` export of `uv-paper` (18 angles of "
        f"incidence, azimuth step 5°, radial step 1°) with {100 * SCATTER:.0f} % lognormal "
        "scatter, thinned by `[bsdf]` for the smaller sizes (`brdf_infer.bench._cost_curve`). "
        f"`posterior` at {CHAINS} chains × ({WARMUP} warmup + {DRAWS} draws) and `report` in "
        "fresh processes with a warm compilation cache; peak memory is the larger of the two "
        "processes' resident sets. Value and gradient: one evaluation of the whitened "
        "potential in a compiled loop.",
        "",
        markdown_table(HEADERS, [row.cells() for row in rows]),
        "",
        *projection,
    ]
