"""The verdict of a posterior run: one record, computed once when the run completes.

Written into the run's ``summary.json`` (``"verdict"``), printed by ``posterior``, ``run`` and
``report`` and rendered by the report as it stands, so that stdout and the report cannot
disagree. It lists, most serious first:

1. the plausibility checks the run was forced past (``--force``,
   :mod:`brdf_infer.plausibility`): an input or a fit that looked wrong before sampling;
2. an implausible answer: a posterior median π·BRDF0 or TIS at the scene's incidence angles
   above 1;
3. every sampler diagnostic that failed its threshold (R-hat, ESS, divergences, BFMI, emcee's
   autocorrelation times; :data:`brdf_infer.posterior.THRESHOLDS`);
4. the rows whose PSIS-LOO Pareto k exceeds :data:`PARETO_K_LIMIT` (the leave-one-out
   estimate, and so the report's model comparisons, are unreliable there).

Empty, the verdict is "every diagnostic passes".
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from brdf_infer.plausibility import answer_checks
from brdf_infer.run_records import Bands, PosteriorSummary

PARETO_K_LIMIT = 0.7
ALL_PASS = "every diagnostic passes"
FORCED = "forced past a plausibility check: "
IMPLAUSIBLE = "implausible answer: "


@dataclass(frozen=True)
class Verdict:
    """What a run's reader must know before trusting it.

    Attributes:
        lines: every check that failed, one line each, most serious first (empty: all pass).
    """

    lines: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        """True when every check passed."""
        return not self.lines

    @property
    def text(self) -> str:
        """The verdict in one line (``verdict: …`` on stdout, the report's verdict box)."""
        return "; ".join(self.lines) if self.lines else ALL_PASS

    def as_json(self) -> dict[str, Any]:
        return {"ok": self.ok, "lines": list(self.lines), "text": self.text}

    @classmethod
    def from_json(cls, payload: dict[str, Any]) -> Verdict:
        return cls(tuple(payload["lines"]))


def posterior_verdict(
    summary: PosteriorSummary,
    bands: Bands,
    theta_i_deg: Sequence[float],
    forced: Sequence[str] = (),
) -> Verdict:
    """The verdict of a posterior run (module docstring).

    Args:
        summary: the run's summary (``diagnostics``, ``predictive`` with ``pareto_k_high``,
            ``pi_brdf0``).
        bands: the run's bands (the TIS band, where the run has one).
        theta_i_deg: the scene's incidence angles [deg], where the TIS is checked.
        forced: the plausibility checks the run was forced past, one line each.
    """
    lines = [FORCED + line for line in forced]
    band = bands.get("tis")
    tis_medians = (
        None
        if band is None
        else np.interp(np.asarray(theta_i_deg, float), band["theta_i_deg"], band["median"])
    )
    pi_brdf0 = summary.get("pi_brdf0")
    lines += [
        IMPLAUSIBLE + found.problem
        for found in answer_checks(
            "the posterior median",
            theta_i_deg,
            tis_medians,
            None if pi_brdf0 is None else pi_brdf0["median"],
        )
    ]
    lines += summary["diagnostics"]["failures"]
    bad = summary["predictive"]["pareto_k_high"]
    if bad:
        lines.append(
            f"{bad} measurement(s) with Pareto k > {PARETO_K_LIMIT} (PSIS-LOO unreliable there)"
        )
    return Verdict(tuple(lines))
