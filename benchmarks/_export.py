"""Benchmark of the exports: the .BSDF grid's own hemisphere integral against the exact TIS
per grid step, and the ABg fits' TIS and shape error against their run time.

With Eq. (10)'s folding (``FOLD``): its steep shoulder at θsf is the harder case for a grid, so
the errors bound those of the default, unfolded export."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from brdf_infer.model import CHECK_QUADRATURE, abg_integral, tis
from brdf_infer.model.params import PAPER_CONSTANTS, UV_PAPER, VIS_PAPER
from brdf_infer.report.export import brdf_table, fit_abg, scatter_grid, table_integral

GRID_STEPS = ((10.0, 2.0), (5.0, 2.0), (5.0, 1.0), (2.0, 0.5))  # (azimuth, radial) [deg]
THETA_I_DEG = np.arange(0.0, 86.0, 5.0)
FOLD = True


@dataclass(frozen=True)
class GridRow:
    params: str
    azimuth_step: float
    radial_step: float
    values: int
    max_error: float
    worst_theta_i: float
    seconds: float

    @property
    def cells(self) -> list[str]:
        return [
            self.params,
            f"{self.azimuth_step:g} / {self.radial_step:g}",
            f"{self.values:,}",
            f"{self.max_error:.1e}",
            f"{self.worst_theta_i:g}",
            f"{self.seconds:.2f}",
        ]


GRID_HEADERS = [
    "parameters",
    "azimuth / radial step [deg]",
    "table values",
    "max abs(table integral / TIS − 1)",
    "at θi [deg]",
    "tables [s]",
]


def grid_rows(quick: bool) -> list[GridRow]:
    """Every (azimuth, radial) step for both published parameter sets, θi = 0, 5, …, 85°."""
    rows = []
    for name, params in (("uv-paper", UV_PAPER), ("vis-paper", VIS_PAPER)):
        exact = np.asarray(tis(THETA_I_DEG, params, FOLD))
        for azimuth, radial in GRID_STEPS[:2] if quick else GRID_STEPS:
            grid = scatter_grid(THETA_I_DEG, azimuth, radial)
            table_of = lambda t, g=grid, p=params: np.asarray(  # noqa: E731
                brdf_table(float(t), g.azimuth_deg, g.radial_deg, p, FOLD, PAPER_CONSTANTS)
            )
            table_of(0.0)  # compile
            clock = time.perf_counter()
            tables = [table_of(t) for t in THETA_I_DEG]
            seconds = time.perf_counter() - clock
            errors = np.array(
                [
                    table_integral(t, grid.azimuth_deg, grid.radial_deg, table) / value - 1.0
                    for t, table, value in zip(THETA_I_DEG, tables, exact, strict=True)
                ]
            )
            worst = int(np.argmax(np.abs(errors)))
            rows.append(
                GridRow(
                    name,
                    azimuth,
                    radial,
                    THETA_I_DEG.size * grid.azimuth_deg.size * grid.radial_deg.size,
                    float(np.abs(errors[worst])),
                    float(THETA_I_DEG[worst]),
                    seconds,
                )
            )
    return rows


@dataclass(frozen=True)
class AbgRow:
    case: str
    max_tis_error: float
    rms_range: tuple[float, float]
    seconds: float
    compile_seconds: float

    @property
    def cells(self) -> list[str]:
        low, high = self.rms_range
        return [
            self.case,
            f"{self.max_tis_error:.1e}",
            f"{low:.3f} – {high:.3f}",
            f"{self.seconds:.2f}",
            f"{self.compile_seconds:.1f}",
        ]


ABG_HEADERS = [
    "fit (uv-paper, θi = 0, 5, …, 85°)",
    "max abs(TIS_ABg / TIS − 1)",
    "rms ln error [-]",
    "time [s]",
    "compile [s]",
]


def abg_rows(quick: bool) -> list[AbgRow]:
    """ABg from the coarse search and from a nearby fit (as over posterior draws). The TIS
    error is A·I with a quadrature finer than the one that set A."""
    theta_i = THETA_I_DEG[::3] if quick else THETA_I_DEG
    exact = np.asarray(tis(theta_i, UV_PAPER, FOLD))
    nearby = UV_PAPER._replace(brdf0=UV_PAPER.brdf0 * 1.05, alpha=UV_PAPER.alpha + 0.1)
    exact_nearby = np.asarray(tis(theta_i, nearby, FOLD))
    rows, start = [], None
    for case, params, exact_tis in (
        ("coarse search + Levenberg–Marquardt", UV_PAPER, exact),
        ("from a nearby fit (per posterior draw)", nearby, exact_nearby),
    ):
        timings = []
        for _ in range(2):  # the first call compiles
            clock = time.perf_counter()
            fit = fit_abg(theta_i, params, exact_tis, FOLD, PAPER_CONSTANTS, start)
            timings.append(time.perf_counter() - clock)
        start = fit
        finer = np.array(
            [
                float(abg_integral(np.log(b), g, np.sin(np.radians(t)), CHECK_QUADRATURE))
                for b, g, t in zip(fit.b, fit.g, theta_i, strict=True)
            ]
        )
        tis_error = np.max(np.abs(fit.a * finer / fit.tis_model - 1.0))
        rms = (float(fit.rms_log_error.min()), float(fit.rms_log_error.max()))
        rows.append(
            AbgRow(case, float(tis_error), rms, timings[1], max(timings[0] - timings[1], 0))
        )
    return rows
