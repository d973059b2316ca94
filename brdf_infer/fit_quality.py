"""How well a least-squares fit describes its data, stated next to its result.

χ² = Σ rᵢ² of the weighted residuals follows a χ² distribution with dof = n − p degrees of
freedom when the model is right and the σᵢ are the rows' true noise. A fit is called **poor**
when both

- χ²/dof > :data:`POOR_CHI2_DOF` = 2: the 1σ from (JᵀJ)⁻¹, which takes the σᵢ at their word,
  then understates the parameters' scatter by more than √2 (41 %), and
- the upper-tail p-value of χ² is below :data:`POOR_P_VALUE` = 0.001: the excess is not the
  chance of a small dof (for the 36 dof of the bundled scene χ²/dof = 2 has p = 3·10⁻⁴; for
  5 dof it has p = 0.075 and is not called poor).

Where the error model learns the repeatability, least squares sets σ_rep so that χ²/dof = 1
(Paule–Mandel, :mod:`brdf_infer.lsq`), and the χ² test says nothing; the misfit shows in σ_rep
instead, which also holds the sample and calibration scatter least squares leaves out. The fit
is then called **poor** when σ_rep is larger than the scene's own error model gives its data:
its prior predictive p-value — the share of 20,000 data sets simulated from the error model,
every noise scale drawn from its prior, whose Paule–Mandel σ̂_rep after the (linearised) fit
reaches the fit's — below :data:`POOR_P_VALUE`
(:func:`brdf_infer._reweighting.repeatability_tail`). On the bundled rows Eq. (7) learns 0.057
in ln R (p = 0.9), ABg 1.88 (p < 5e-5): one value at specular for every θi cannot follow data
that grow 100-fold there. This judges the model by the noise the scene expects, not the
structure of its residuals: a small systematic misfit passes (the comparison by PSIS-LOO sees
more).

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
TAIL_DRAWS = 20_000  # simulated data sets of a repeatability's p-value (resolution 5e-5)


@dataclass(frozen=True)
class FitQuality:
    """χ² per degree of freedom of a fit, its p-value and a statement in words.

    Attributes:
        chi2: the weighted sum of squared residuals at the optimum.
        dof: degrees of freedom, rows − free parameters.
        learned_repeatability: σ_rep [ln R] when it was set so that χ²/dof = 1 (Paule–Mandel;
            :mod:`brdf_infer.lsq`), else None.
        repeatability_p_value: the prior predictive p-value of a learned σ_rep (module
            docstring; None: not judged).
    """

    chi2: float
    dof: int
    learned_repeatability: float | None = None
    repeatability_p_value: float | None = None

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
        if self.learned_repeatability is not None:
            tail = self.repeatability_p_value
            return bool(tail is not None and tail < POOR_P_VALUE)
        return bool(self.chi2_dof > POOR_CHI2_DOF and self.p_value < POOR_P_VALUE)

    @property
    def statement(self) -> str:
        """The quality in one line, starting with ``poor:``, ``ok:`` or ``undefined:``."""
        if self.dof <= 0:
            return "undefined: no degrees of freedom left (as many parameters as rows)"
        p = f"p = {self.p_value:.2g}" if self.p_value > 0 else "p < 1e-300"
        measured = f"χ²/dof = {self.chi2_dof:.3g} for {self.dof} dof ({p})"
        if self.learned_repeatability is not None:
            learned = f"the learned repeatability {self.learned_repeatability:.3g} (in ln R)"
            if self.poor:
                tail = self.repeatability_p_value
                tail_text = f"p = {tail:.2g}" if tail > 0 else f"p < {1 / TAIL_DRAWS:.0e}"
                return (
                    f"poor: {measured}, by construction; but {learned} is more than the "
                    f"scene's error model gives its data (prior predictive {tail_text}): the "
                    "model leaves scatter the error model does not expect, and its 1σ belong "
                    "to a model the data reject"
                )
            judged = (
                ""
                if self.repeatability_p_value is None
                else f", prior predictive p = {self.repeatability_p_value:.2g},"
            )
            return (
                f"ok: {measured}, by construction: {learned}{judged} holds every scatter "
                "beyond the rows' own σ"
            )
        if self.poor:
            return (
                f"poor: {measured}: the model does not describe the data within their σ; the "
                f"unscaled 1σ understates the uncertainty by a factor {self.sigma_factor:.3g}, "
                "and even the scaled one belongs to a model the data reject"
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
