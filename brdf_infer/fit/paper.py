"""The paper's fit (Sec. 4.2): linear regression of ln BRDF for fixed (α, θs0), and a grid
search over (α, θs0).

For fixed α and θs0, Eq. (7) is linear in (ln BRDF0, a1, a2, a3) on the basis
[1, θi x, θi x^α, θi² x^α], x = θs − θs0 (x^α := 0 below θs0). Measured BRDFs come from raw
reflectance through Eq. (6). Which rows enter changes the answer;
:data:`brdf_infer.tables.selections.SELECTIONS` names the choices, and ``paper`` is the one that
reproduces Sec. 5.3.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from brdf_infer._internal.precision import ensure_float64
from brdf_infer.errors import BadInputError
from brdf_infer.model import log_brdf_inplane
from brdf_infer.model.params import Params
from brdf_infer.scene import Scene
from brdf_infer.tables.measurements import Measurements
from brdf_infer.tables.selections import SELECTIONS


@dataclass(frozen=True)
class PaperFitResult:
    """Result of the linear regression.

    Attributes:
        params: fitted parameters, α and θs0 as fixed [paper units].
        sigma_e: mean |ln BRDF_fit − ln BRDF_meas| over the fitted points (σE, Sec. 4.2) [-].
        sigma_re: mean relative error |BRDF_fit − BRDF_meas| / BRDF_meas (σRE) [-].
        n_points: number of fitted points.
        residuals: ln BRDF_fit − ln BRDF_meas per fitted point.
        points: the fitted rows.
    """

    params: Params
    sigma_e: float
    sigma_re: float
    n_points: int
    residuals: np.ndarray
    points: Measurements


def select_points(scene: Scene, measurements: Measurements, selection: str) -> Measurements:
    """Apply a named :data:`SELECTIONS` entry to a measurement table.

    Raises:
        BadInputError: unknown selection name.
    """
    if selection not in SELECTIONS:
        raise BadInputError(
            f"unknown selection {selection!r} (known: {', '.join(SELECTIONS)})",
            field="selection",
        )
    rule = SELECTIONS[selection]
    rows = measurements.subset(~measurements.out_of_plane)  # Eq. (7) is the in-plane model
    if rule.drop_repeated_geometry:
        keep = np.ones(len(rows), bool)
        seen: set[tuple[float, float]] = set()
        for name in scene.series:
            in_series = rows.series == name
            geometry = set(
                zip(rows.theta_i_deg[in_series], rows.theta_s_deg[in_series], strict=True)
            )
            for index in np.flatnonzero(in_series):
                if (rows.theta_i_deg[index], rows.theta_s_deg[index]) in seen:
                    keep[index] = False
            seen |= geometry
        rows = rows.subset(keep)
    if rule.average_samples:
        rows = _average_samples(rows)
    return rows


def _average_samples(rows: Measurements) -> Measurements:
    """One row per (series, θi, θs): mean reflectance; σ from Eq. (5), √(mean σ²)."""
    keys = list(zip(rows.series, rows.theta_i_deg, rows.theta_s_deg, strict=True))
    unique = list(dict.fromkeys(keys))
    groups = [np.array([k == u for k in keys]) for u in unique]
    return Measurements(
        path=rows.path,
        series=np.array([u[0] for u in unique]),
        sample=np.array(
            [rows.sample[g][0] if g.sum() == 1 else f"mean of {g.sum()}" for g in groups]
        ),
        theta_i_deg=np.array([u[1] for u in unique]),
        theta_s_deg=np.array([u[2] for u in unique]),
        reflectance=np.array([rows.reflectance[g].mean() for g in groups]),
        reflectance_err=None
        if rows.reflectance_err is None
        else np.array([np.sqrt(np.mean(rows.reflectance_err[g] ** 2)) for g in groups]),
    )


def measured_log_brdf(scene: Scene, rows: Measurements) -> np.ndarray:
    """ln BRDF of each row from its raw reflectance through Eq. (6) (BRDF rows as they are)."""
    return scene.measured_log_brdf(rows)


def regression_basis(
    theta_i_deg: np.ndarray, theta_s_deg: np.ndarray, alpha: float, theta_s0_deg: float
) -> np.ndarray:
    """Design matrix [1, θi x, θi x^α, θi² x^α] of Sec. 4.2, x = max(θs − θs0, 0)."""
    x = np.maximum(theta_s_deg - theta_s0_deg, 0.0)
    x_alpha = x**alpha
    return np.stack(
        [np.ones_like(x), theta_i_deg * x, theta_i_deg * x_alpha, theta_i_deg**2 * x_alpha], 1
    )


def paper_fit(
    scene: Scene,
    measurements: Measurements,
    *,
    alpha: float | None = None,
    theta_s0_deg: float | None = None,
    selection: str | None = None,
) -> PaperFitResult:
    """The paper's linear regression of ln BRDF (Sec. 4.2) for fixed α and θs0.

    The columns of the design matrix differ by ~10 orders of magnitude (x^4.5 ~ 1e7); they are
    scaled to unit norm before the least-squares solve.

    Args:
        scene: supplies the apertures and the defaults of the three options below.
        measurements: the scene's measurement table.
        alpha: fixed α [-] (default: the scene's ``paper_fit.alpha``).
        theta_s0_deg: fixed θs0 [deg] (default: the scene's).
        selection: a :data:`SELECTIONS` name (default: the scene's).

    Raises:
        BadInputError: fewer selected points than the four linear coefficients.
    """
    ensure_float64()
    settings = scene.paper_fit
    alpha = settings.alpha if alpha is None else alpha
    theta_s0_deg = settings.theta_s0_deg if theta_s0_deg is None else theta_s0_deg
    rows = select_points(
        scene, measurements, settings.selection if selection is None else selection
    )
    if len(rows) < 4:
        raise BadInputError(
            f"the paper fit needs at least 4 points, the selection has {len(rows)}",
            file=measurements.path,
        )
    target = measured_log_brdf(scene, rows)
    basis = regression_basis(rows.theta_i_deg, rows.theta_s_deg, alpha, theta_s0_deg)
    scale = np.linalg.norm(basis, axis=0)
    scale[scale == 0] = 1.0
    scaled, *_ = np.linalg.lstsq(basis / scale, target, rcond=None)
    log_brdf0, a1, a2, a3 = scaled / scale
    params = Params(float(np.exp(log_brdf0)), float(a1), float(a2), float(a3), alpha, theta_s0_deg)
    fitted = np.asarray(log_brdf_inplane(rows.theta_i_deg, rows.theta_s_deg, params))
    residuals = fitted - target
    return PaperFitResult(
        params=params,
        sigma_e=float(np.mean(np.abs(residuals))),
        sigma_re=float(np.mean(np.abs(np.expm1(residuals)))),
        n_points=len(rows),
        residuals=residuals,
        points=rows,
    )


@dataclass(frozen=True)
class GridSearchResult:
    """The (α, θs0) grid search of Sec. 4.2.

    Attributes:
        best: the regression at the grid point of least ``sigma_tre``.
        alphas: grid of α [-].
        theta_s0s_deg: grid of θs0 [deg].
        sigma_tre: total relative error over *all* rows of the table (not only the selected
            ones, as the paper's σTRE), shape (len(alphas), len(theta_s0s_deg)).
    """

    best: PaperFitResult
    alphas: np.ndarray
    theta_s0s_deg: np.ndarray
    sigma_tre: np.ndarray


def paper_grid_search(
    scene: Scene,
    measurements: Measurements,
    alphas: np.ndarray,
    theta_s0s_deg: np.ndarray,
    *,
    selection: str | None = None,
) -> GridSearchResult:
    """Regress at every (α, θs0) and keep the one of least total relative error σTRE.

    σTRE is evaluated over every in-plane row of ``measurements`` (each sample individually),
    the analogue of the paper's "all available data points".
    """
    measurements = measurements.subset(~measurements.out_of_plane)
    all_log_brdf = measured_log_brdf(scene, measurements)
    table = np.empty((len(alphas), len(theta_s0s_deg)))
    best, best_value = None, np.inf
    for i, alpha in enumerate(alphas):
        for j, theta_s0 in enumerate(theta_s0s_deg):
            result = paper_fit(
                scene,
                measurements,
                alpha=float(alpha),
                theta_s0_deg=float(theta_s0),
                selection=selection,
            )
            predicted = np.asarray(
                log_brdf_inplane(measurements.theta_i_deg, measurements.theta_s_deg, result.params)
            )
            table[i, j] = np.mean(np.abs(np.expm1(predicted - all_log_brdf)))
            if table[i, j] < best_value:
                best, best_value = result, table[i, j]
    return GridSearchResult(best, np.asarray(alphas), np.asarray(theta_s0s_deg), table)
