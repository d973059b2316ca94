"""Benchmark of sampling robustness: NUTS with default settings on the bundled scene for many
seeds, and on measurement geometries unlike the bundled one (synthetic data)."""

from __future__ import annotations

import tempfile
from dataclasses import dataclass

from brdf_infer.params import UV_PAPER
from brdf_infer.posterior import run_posterior
from brdf_infer.scene import Scene, load_scene
from brdf_infer.synthetic import GEOMETRIES, write_geometry_scene


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
