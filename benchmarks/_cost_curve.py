"""The benchmark's cost curve: what a run costs as the rows grow from the bundled 42 to a
whole imaging-scatterometer table (issue 35).

The tables are one full-grid ``.BSDF`` export of the parameter set ``uv-paper`` (18 angles of
incidence 0–85°, azimuth step 5°, radial step 1°: 37 × 176 × 18 cells, 59 585 of them above
the horizon and positive), each value multiplied by exp(0.05 ε), ε ~ N(0, 1), and read
through the scene's ``[bsdf]`` thinning for the smaller sizes. Each size runs ``brdf-infer
posterior`` (default settings: NUTS on the bundled rows, Laplace + PSIS on the tables) and
``brdf-infer report`` in fresh processes sharing one compilation cache, each twice below
10⁴ rows, the first filling the cache, once from there (the run's own ``compile`` seconds are
apart from its sampling in either case); the
value-and-gradient time is measured in this process.
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

from benchmarks._tables import markdown_table
from brdf_infer.runs.folder import RunFolder

SCATTER = 0.05  # lognormal 1σ of the synthetic table's values
SIZES = (  # label, [bsdf] keep_every_radial, keep_every_azimuth (None: the bundled scene)
    ("bundled", None, None),
    ("2 × 10³", 10, 3),
    ("2 × 10⁴", 3, 1),
    ("6 × 10⁴ (full grid)", 1, 1),
)
ONE_RUN_ROWS = 10**4  # from here a size runs once (module docstring)
HEADERS = [
    "table",
    "rows",
    "sampler",
    "value and gradient [µs]",
    "[µs / row]",
    "posterior wall [s]",
    "of it compiling [s]",
    "sampling [s]",
    "after sampling [s]",
    "of it LOO [s]",
    "of it answer records [s]",
    "report [s]",
    "peak memory [GiB]",
    "posterior.nc [MB]",
]


@dataclass(frozen=True)
class CostRow:
    """One size of the curve (units in :data:`HEADERS`)."""

    label: str
    rows: int
    sampler: str
    gradient_us: float
    posterior_s: float
    compile_s: float
    sampling_s: float
    after_sampling_s: float
    loo_s: float  # PSIS-LOO with the exact refits of rows of Pareto k > 0.7
    answer_s: float  # width (with its variants' refits), learned, reference
    report_s: float
    peak_gib: float
    netcdf_mb: float

    def cells(self) -> list[str]:
        return [
            self.label,
            f"{self.rows}",
            self.sampler,
            f"{self.gradient_us:.0f}",
            f"{self.gradient_us / self.rows:.2f}",
            f"{self.posterior_s:.1f}",
            f"{self.compile_s:.1f}",
            f"{self.sampling_s:.1f}",
            f"{self.after_sampling_s:.1f}",
            f"{self.loo_s:.1f}",
            f"{self.answer_s:.1f}",
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


def cost_row(label: str, scene: str, scratch: Path, cache: Path, once: bool = False) -> CostRow:
    """One size: the gradient here, then ``posterior`` and ``report`` in fresh processes, each
    twice below :data:`ONE_RUN_ROWS` rows (the first fills the compilation cache; the second is
    measured), once from there or when ``once`` (its compile seconds are apart in the
    table)."""
    import json

    rows, gradient = scene_gradient(scene)
    for attempt in range(1 if once or rows >= ONE_RUN_ROWS else 2):
        out = scratch / f"run-{rows}-{attempt}"
        argv = ["posterior", scene, "--out", str(out), "--json"]
        wall, peak, output = measured_process(argv, cache)
        summary = json.loads(output)
        report_wall, report_peak, _ = measured_process(["report", str(out)], cache)
    seconds = summary["seconds"]
    return CostRow(
        label=label,
        rows=rows,
        sampler=summary["sampler"],
        gradient_us=gradient,
        posterior_s=wall,
        compile_s=float(seconds.get("compile", 0.0)),
        sampling_s=float(seconds["sampling"]),
        after_sampling_s=float(sum(seconds["after_sampling"].values())),
        loo_s=float(seconds["after_sampling"]["loo"]),
        answer_s=float(seconds["after_sampling"]["answer"]),
        report_s=report_wall,
        peak_gib=max(peak, report_peak),
        netcdf_mb=RunFolder(out).posterior_file.stat().st_size / 1e6,
    )


def scene_gradient(scene: str, evaluations: int | None = None) -> tuple[int, float]:
    """(rows, value-and-gradient [µs]) of a scene's whitened potential, averaged over
    ``evaluations`` in a compiled loop (default: 4 × 10⁶ row-evaluations, 20 to 4000)."""
    from benchmarks._speed import gradient_microseconds
    from brdf_infer.posterior import FlatPotential, build_model
    from brdf_infer.scene import load_scene

    loaded = load_scene(scene)
    rows = loaded.load_measurements()
    model = build_model(loaded, rows)
    if evaluations is None:
        evaluations = int(max(20, min(4000, 4e6 // len(rows))))
    return len(rows), gradient_microseconds(FlatPotential(model), model.data, evaluations)


def cost_rows(quick: bool, progress=print) -> list[CostRow]:
    """The curve (module docstring); ``quick``: the two smallest sizes only, each run once."""
    rows = []
    with tempfile.TemporaryDirectory() as scratch_name:
        scratch = Path(scratch_name)
        table = write_table(scratch)
        for label, radial, azimuth in SIZES[: 2 if quick else None]:
            scene = "lya" if radial is None else str(scene_file(scratch, table, radial, azimuth))
            progress(f"cost curve: {label} ...")
            rows.append(cost_row(label, scene, scratch, scratch / "cache", once=quick))
    return rows


def cost_section(rows: list[CostRow], quick: bool = False) -> list[str]:
    """The report's section of the curve (``quick``: each size was run once)."""
    runs = (
        "each run once (the compilation cache cold; its compile time is its own column)"
        if quick
        else "below 10⁴ rows each run twice and the second measured (the compilation cache "
        "filled by the first), from there once (its compile time is its own column either way)"
    )
    return [
        "## Cost against the number of rows",
        "",
        f"Whole instrument tables: a full-grid `.BSDF` export of `uv-paper` (18 angles of "
        f"incidence, azimuth step 5°, radial step 1°) with {100 * SCATTER:.0f} % lognormal "
        "scatter, thinned by `[bsdf]` for the smaller sizes (`benchmarks._cost_curve`). "
        "`posterior` at its defaults (4 × 1000 draws; `auto`: NUTS with 1000 warmup "
        "iterations on the bundled rows, Laplace + PSIS from 1000 rows) and `report`, each "
        f"in a fresh process, {runs}; peak memory is the larger of the two processes' "
        "resident sets. "
        "Value and gradient: one evaluation of the whitened potential in a compiled loop "
        "(what a NUTS step costs per leapfrog step).",
        "",
        markdown_table(HEADERS, [row.cells() for row in rows]),
        "",
    ]
