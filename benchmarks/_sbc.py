"""Benchmark of simulation-based calibration: the bundled scene as built, and with faults
planted in the inference that the check must flag (the likelihood's σ 35 % too wide, the
whitening's log-Jacobian dropped, every free prior moved by one prior sd)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from brdf_infer.scene import Scene, check_instrument
from brdf_infer.studies.sbc import SbcResult, SbcSettings, run_sbc

PLANTED_SIGMA_SCALE = 1.35


@dataclass(frozen=True)
class SbcRow:
    case: str
    result: SbcResult

    @property
    def cells(self) -> list[str]:
        r = self.result
        low, high = r.coverage_range[0.9]
        coverage = [r.coverage[0.9][q] for q in r.quantities]
        per_replicate = (r.seconds - r.compile_seconds) / r.settings.replicates
        return [
            self.case,
            str(r.settings.replicates),
            "pass" if r.passed else f"fail ({len(r.failures)})",
            f"{min(r.chi2_p[q] for q in r.quantities):.2g}",
            f"{min(r.ks_p[q] for q in r.quantities):.2g}",
            f"{min(coverage):.1%}–{max(coverage):.1%} (allowed {low:.1%}–{high:.1%})",
            f"{int(np.sum(r.divergences > 0))}",
            f"{r.seconds:.0f}",
            f"{per_replicate:.2f}",
            f"{r.compile_seconds:.1f}",
        ]


HEADERS = [
    "case",
    "replicates",
    "verdict",
    "min χ² p",
    "min KS p",
    "90 % coverage",
    "replicates with divergences",
    "wall [s]",
    "per replicate [s]",
    "compile [s]",
]


FAMILY_MODEL = "abg"  # another family through the same check
INSTRUMENT = "image"  # a likelihood through the measurement kernel


def planted_cases(model: str | None) -> list[tuple[str, dict]]:
    """The (case, settings) of one family's rows: as built and each planted fault that applies
    (the machinery faults are for ``strumik2024``, the scene's own family)."""
    cases = [("as built", {}), ("planted: σ × 1.35", {"sigma_scale": PLANTED_SIGMA_SCALE})]
    if model is None:
        cases += [
            ("planted: log-Jacobian dropped", {"planted_fault": "jacobian"}),
            ("planted: priors moved 1 sd", {"planted_fault": "prior"}),
        ]
    return cases


def sbc_rows(scene: Scene, quick: bool, progress=print) -> list[SbcRow]:
    """SBC of ``scene`` as built and with each planted fault (:func:`planted_cases`), for
    ``strumik2024`` and for :data:`FAMILY_MODEL` (the first two rows are the scene's own family
    as built and with σ × 1.35), and of the :data:`INSTRUMENT` kernel's likelihood as built
    (100 replicates)."""
    size = {"replicates": 6, "draws": 30, "thin": 1, "warmup": 150} if quick else {}
    measurements = scene.load_measurements()
    rows = []
    for model in (None, FAMILY_MODEL):
        prefix = "" if model is None else f"{model}: "
        for case, planted in planted_cases(model):
            settings = SbcSettings(**planted, **size)
            progress(f"  SBC, {prefix}{case}, {settings.replicates} replicates")
            result = run_sbc(scene, measurements, settings, model=model)
            rows.append(SbcRow(prefix + case, result))
    kernel = {**size, "replicates": 6 if quick else 100}
    progress(f"  SBC, {INSTRUMENT} instrument kernel, as built, {kernel['replicates']} replicates")
    result = run_sbc(check_instrument(scene, INSTRUMENT), measurements, SbcSettings(**kernel))
    rows.append(SbcRow(f"{INSTRUMENT} instrument: as built", result))
    return rows
