"""Benchmark of robustness: NUTS with default settings on the bundled scene for many seeds and
on measurement geometries unlike the bundled one (synthetic data); and every loader of user
files on thousands of generated bad inputs (:mod:`benchmarks._loader_inputs`)."""

from __future__ import annotations

import tempfile
import time
import traceback
from collections import Counter
from dataclasses import dataclass

from brdf_infer.model.params import UV_PAPER
from brdf_infer.posterior import run_posterior
from brdf_infer.scene import Scene, load_scene
from brdf_infer.studies.synthetic import GEOMETRIES, write_geometry_scene


@dataclass(frozen=True)
class RobustnessRow:
    scene: str
    seed: int
    divergences: int
    r_hat_max: float
    ess_bulk_min: float
    ess_tail_min: float
    sampling_seconds: float

    @property
    def cells(self) -> list[str]:
        return [
            self.scene,
            str(self.seed),
            str(self.divergences),
            f"{self.r_hat_max:.4f}",
            f"{self.ess_bulk_min:.0f}",
            f"{self.ess_tail_min:.0f}",
            f"{self.sampling_seconds:.1f}",
        ]


HEADERS = ["scene", "seed", "divergences", "max R-hat", "min bulk ESS", "min tail ESS", "[s]"]


def _row(label: str, scene: Scene, seed: int) -> RobustnessRow:
    run = run_posterior(scene, scene.load_measurements(), seed=seed, progress=False)
    diagnostics = run.summary["diagnostics"]
    return RobustnessRow(
        label,
        seed,
        diagnostics["divergences"],
        diagnostics["r_hat_max"],
        diagnostics["ess_bulk_min"],
        diagnostics["ess_tail_min"],
        run.summary["seconds"]["sampling"],
    )


def robustness_rows(scene: Scene, quick: bool, progress=print) -> list[RobustnessRow]:
    """Default NUTS on ``scene`` for seeds 0–15 (quick: 0–1) and on each synthetic geometry
    for seeds 0–2 (quick: 0)."""
    rows = []
    for seed in range(2 if quick else 16):
        progress(f"  {scene.name}, seed {seed}")
        rows.append(_row(scene.name, scene, seed))
    with tempfile.TemporaryDirectory() as folder:
        for geometry in GEOMETRIES:
            for seed in range(1 if quick else 3):
                progress(f"  synthetic {geometry}, seed {seed}")
                path = write_geometry_scene(f"{folder}/{geometry}{seed}", geometry, UV_PAPER, seed)
                rows.append(_row(f"synthetic {geometry}", load_scene(path), seed))
    return rows


@dataclass(frozen=True)
class LoaderRow:
    """One loader on generated inputs: how many it read, refused in one line, or failed on
    (any other exception, a broken promise, a file written: ``failures`` holds the first)."""

    loader: str
    inputs: int
    read: int
    refused: int
    failed: int
    seconds: float
    failures: tuple[str, ...] = ()

    @property
    def cells(self) -> list[str]:
        return [
            self.loader,
            f"{self.inputs:,}",
            f"{self.read:,}",
            f"{self.refused:,}",
            str(self.failed),
            f"{self.seconds:.0f}",
        ]


LOADER_HEADERS = [
    "loader",
    "generated inputs",
    "read",
    "refused in one line (exit 2)",
    "tracebacks or broken promises",
    "[s]",
]


def loader_rows(examples: int, progress=print) -> list[LoaderRow]:
    """Each loader on ``examples`` generated inputs (Hypothesis, derandomized: the same inputs
    every time), counted; a failure is counted and listed, not raised."""
    from benchmarks._loader_inputs import LOADERS, run_loader

    rows = []
    for loader in LOADERS.values():
        progress(f"  {loader.name}: {examples} generated inputs")
        started = time.perf_counter()
        counts, failures = _count_outcomes(loader, examples, run_loader)
        rows.append(
            LoaderRow(
                loader.name,
                sum(counts.values()),
                counts["read"],
                counts["refused"],
                counts["failed"],
                time.perf_counter() - started,
                tuple(failures[:3]),
            )
        )
    return rows


def _count_outcomes(loader, examples: int, run_loader) -> tuple[Counter[str], list[str]]:
    """(read / refused / failed counts, the failures) of ``loader`` on ``examples`` inputs."""
    from hypothesis import HealthCheck, Phase, given, settings

    counts: Counter[str] = Counter()
    failures: list[str] = []

    @settings(
        max_examples=examples,
        database=None,
        deadline=None,
        derandomize=True,
        phases=[Phase.generate],
        suppress_health_check=list(HealthCheck),
    )
    @given(loader.inputs())
    def one(generated) -> None:
        try:
            refusal = run_loader(loader, generated)
        except Exception as error:  # counted: the benchmark reports, the tests fail
            counts["failed"] += 1
            where = traceback.extract_tb(error.__traceback__)[-1]
            failures.append(f"{type(error).__name__}: {error} ({where.name}) on {generated}")
            return
        counts["read" if refusal is None else "refused"] += 1

    one()
    return counts, failures
