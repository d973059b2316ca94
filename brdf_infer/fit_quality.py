"""How well a least-squares fit describes its data, stated next to its result.

χ² = Σ rᵢ² of the weighted residuals follows a χ² distribution with dof = n − p degrees of
freedom when the model is right and the σᵢ are the rows' true noise. A fit is called **poor**
when both

- χ²/dof > :data:`POOR_CHI2_DOF` = 2: the 1σ from (JᵀJ)⁻¹, which takes the σᵢ at their word,
  then understates the parameters' scatter by more than √2 (41 %), and
- the upper-tail p-value of χ² is below :data:`POOR_P_VALUE` = 0.001: the excess is not the
  chance of a small dof (for the 36 dof of the bundled scene χ²/dof = 2 has p = 3·10⁻⁴; for
  5 dof it has p = 0.075 and is not called poor).

Every fit also gives its 1σ scaled by √(χ²/dof) (the Birge ratio), the uncertainty the
parameters would have if the misfit were noise the σᵢ left out. A poor fit's scaled 1σ is
still a statement about a model that does not describe the data: a comparison by the data
(``brdf-infer compare``) is the better judge of such a model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from scipy.stats import chi2 as chi2_distribution

POOR_CHI2_DOF = 2.0
POOR_P_VALUE = 1e-3


@dataclass(frozen=True)
class FitQuality:
    """χ² per degree of freedom of a fit, its p-value and a statement in words.

    Attributes:
        chi2: the weighted sum of squared residuals at the optimum.
        dof: degrees of freedom, rows − free parameters.
        learned_repeatability: σ_rep [ln R] when it was set so that χ²/dof = 1 (Paule–Mandel;
            :mod:`brdf_infer.lsq`), else None.
    """

    chi2: float
    dof: int
    learned_repeatability: float | None = None

    @property
    def chi2_dof(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else math.nan

    @property
    def p_value(self) -> float:
        """P(χ² ≥ the fit's χ²) for a right model with right σ."""
        return float(chi2_distribution.sf(self.chi2, self.dof)) if self.dof > 0 else math.nan

    @property
    def sigma_factor(self) -> float:
        """√(χ²/dof): what the 1σ is multiplied by when scaled (1 where undefined)."""
        return math.sqrt(self.chi2_dof) if self.dof > 0 and self.chi2 > 0 else 1.0

    @property
    def poor(self) -> bool:
        return bool(self.chi2_dof > POOR_CHI2_DOF and self.p_value < POOR_P_VALUE)

    @property
    def statement(self) -> str:
        """The quality in one line, starting with ``poor:``, ``ok:`` or ``undefined:``."""
        if self.dof <= 0:
            return "undefined: no degrees of freedom left (as many parameters as rows)"
        p = f"p = {self.p_value:.2g}" if self.p_value > 0 else "p < 1e-300"
        measured = f"χ²/dof = {self.chi2_dof:.3g} for {self.dof} dof ({p})"
        if self.poor:
            return (
                f"poor: {measured}: the model does not describe the data within their σ; the "
                f"unscaled 1σ understates the uncertainty by a factor {self.sigma_factor:.3g}, "
                "and even the scaled one belongs to a model the data reject"
            )
        if self.learned_repeatability is not None:
            return (
                f"ok: {measured}, by construction: the learned repeatability "
                f"{self.learned_repeatability:.3g} (in ln R) holds every scatter beyond the "
                "rows' own σ"
            )
        return f"ok: {measured}"

    def as_json(self) -> dict[str, Any]:
        """The keys a fit's JSON carries: ``chi2_dof``, ``dof``, ``chi2_p_value``,
        ``poor_fit`` and ``fit_quality`` (the statement)."""
        return {
            "chi2_dof": self.chi2_dof,
            "dof": self.dof,
            "chi2_p_value": self.p_value,
            "poor_fit": self.poor,
            "fit_quality": self.statement,
        }


def scaled_sigma(sigma: dict[str, float], factor: float) -> dict[str, float]:
    """Every 1σ multiplied by ``factor`` (√(χ²/dof): the covariance scaled by χ²/dof)."""
    return {name: value * factor for name, value in sigma.items()}
