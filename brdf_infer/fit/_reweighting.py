"""The per-row σ of least squares (:mod:`brdf_infer.fit.lsq`) of any family, reweighted after each
solve: the angle terms at the current parameters and, where the repeatability is learned, σ_rep
by the Paule–Mandel condition."""

from __future__ import annotations

import numpy as np

from brdf_infer.model import ModelFamily, Physical
from brdf_infer.model.error_model import NoiseLayout, angle_slopes
from brdf_infer.predict.observations import family_log_reflectance_at, log_reflectance
from brdf_infer.scene import Scene

REWEIGHT_TOLERANCE = 1e-6  # relative change of every σ_i that ends the reweighting


class Reweighting:
    """The per-row σ of least squares, updated after each solve (:mod:`brdf_infer.fit.lsq`'s
    docstring)."""

    def __init__(self, scene: Scene, model, member: ModelFamily, n_free: int, layout: NoiseLayout):
        errors = scene.errors
        self.model, self.member, self.errors, self.layout = model, member, errors, layout
        self.value_variance = np.asarray(model.data.sigma) ** 2
        self.generative = errors.model == "generative"
        self.dof = model.n_points - n_free
        self.learned = self.generative and errors.learns_repeatability and self.dof > 0
        if not self.generative:
            self.repeatability = 0.0
        elif errors.learns_repeatability:
            self.repeatability = errors.reflectance_rel  # starting value, then Paule–Mandel
        else:
            self.repeatability = float(errors.repeatability)
        self.angle_variance = np.zeros_like(self.value_variance)
        self.rotation_slope = np.zeros_like(self.value_variance)  # g_rot [ln R / deg]
        self.sigma = self._sigma()
        self.solves = 0

    def _sigma(self) -> np.ndarray:
        return np.sqrt(self.value_variance + self.repeatability**2 + self.angle_variance)

    def update(self, physical: Physical) -> bool:
        """Recompute σ at the family's parameters ``physical``; True when it changed enough to
        solve again."""
        self.solves += 1
        if not self.generative:
            return False
        data, errors, layout = self.model.data, self.errors, self.layout
        if errors.angles_on:
            g_rot, g_cam = angle_slopes(
                lambda ti, ts: family_log_reflectance_at(self.member, ti, ts, physical, data),
                data.theta_i_deg,
                data.theta_s_deg,
                layout.theta_s_per_rotation,
            )
            self.rotation_slope = np.asarray(g_rot)
            self.angle_variance = np.asarray(
                (g_rot * layout.rotation_deg) ** 2 + (g_cam * layout.camera_deg) ** 2
            )
        if self.learned:
            residuals = np.asarray(
                log_reflectance(self.member, physical, data) - data.log_reflectance
            )
            self.repeatability = paule_mandel(
                residuals, self.value_variance + self.angle_variance, self.dof
            )
        previous, self.sigma = self.sigma, self._sigma()
        return bool(np.max(np.abs(self.sigma / previous - 1.0)) > REWEIGHT_TOLERANCE)


def paule_mandel(residuals: np.ndarray, variances: np.ndarray, dof: float) -> float:
    """The s ≥ 0 with Σ rᵢ²/(vᵢ + s²) = dof (Paule & Mandel 1982), by bisection.

    0 when the rows already scatter no more than their variances say (χ²/dof ≤ 1). Any other
    target value of the sum gives the ends of σ_rep's Q-profile interval
    (:func:`brdf_infer.fit.quality.repeatability_check`).
    """
    return float(paule_mandel_many(np.asarray(residuals, float)[None], variances, dof, 200)[0])


def paule_mandel_many(
    residuals: np.ndarray, variances: np.ndarray, dof: float, iterations: int = 60
) -> np.ndarray:
    """:func:`paule_mandel` of every row of ``residuals`` (sets × rows) at once, by bisection
    (60 halvings by default: the bracket shrinks 2⁶⁰-fold, below any σ's meaning)."""
    residuals, variances = np.asarray(residuals, float), np.asarray(variances, float)
    squares = residuals**2

    def excess(s: np.ndarray) -> np.ndarray:
        total = variances + s[:, None] ** 2
        safe = np.where(total > 0, total, 1.0)
        terms = np.where(total > 0, squares / safe, np.where(squares == 0, 0.0, np.inf))
        return np.sum(terms, axis=1) - dof

    low = np.zeros(len(residuals))
    high = np.sqrt(np.sum(squares, axis=1) / dof)
    for _ in range(iterations):
        middle = 0.5 * (low + high)
        above = excess(middle) > 0
        low, high = np.where(above, middle, low), np.where(above, high, middle)
    return np.where(excess(np.zeros(len(residuals))) <= 0, 0.0, high)
