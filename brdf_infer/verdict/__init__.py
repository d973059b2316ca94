"""The verdict of a posterior run: one record, computed once when the run completes.

Written into the run's ``summary.json`` (``"verdict"``), printed by ``posterior``, ``run`` and
``report`` and rendered by the report as it stands, so that stdout and the report cannot
disagree. It lists, most serious first:

1. the plausibility checks the run was forced past (``--force``,
   :mod:`brdf_infer.verdict.plausibility`): an input or a fit that looked wrong before sampling;
2. an implausible answer: a posterior median π·BRDF0 or TIS at the scene's incidence angles
   above 1;
3. every sampler diagnostic that failed its threshold (R-hat, ESS, divergences, BFMI, emcee's
   autocorrelation times; :data:`brdf_infer.posterior.THRESHOLDS`);
4. the rows whose PSIS-LOO Pareto k exceeds :func:`pareto_k_limit` of its draws (the leave-one-out
   estimate, and so the report's model comparisons, are unreliable there), each named by its
   series, sample, angles and k, unless the run computed their terms exactly by refitting
   without them (:mod:`brdf_infer.posterior._loo_refit`), which makes them a fact.

Empty, the verdict is "every diagnostic passes". Beside these failures it states *facts* a
reader of the answer must know, which are not failures: an assumption of the error model that
alone carries more than a third of a headline 95 % width (TIS(70°), π·BRDF0;
:mod:`brdf_infer.posterior._width`), a learned noise scale the data do not contract (set by
its prior), a published reference value outside the 95 % interval, and, first, how many cells
of a .BSDF table each reading rule left out (zero cells, dropouts, positive cells below the
horizon; :mod:`brdf_infer.tables.screening`; nothing for a CSV or a table no rule touched).

The package is how far to trust an answer: this verdict, and ``plausibility``, the checks of the
inputs and the answers that it reads (and that stop a job before sampling).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from brdf_infer.runs.records import Bands, PosteriorSummary
from brdf_infer.tables.screening import table_facts
from brdf_infer.verdict.plausibility import answer_checks

PARETO_K_LIMIT = 0.7  # above it importance weights are unreliable whatever S (PSIS paper, Sec. 3)
ALL_PASS = "every diagnostic passes"


def pareto_k_limit(samples: int) -> float:
    """The largest Pareto k̂ of a reliable importance-sampling estimate from ``samples``
    draws: min(1 − 1/log₁₀ S, :data:`PARETO_K_LIMIT`) (Vehtari et al. 2024, JMLR 25(72),
    Sec. 3; ArviZ's ``loo`` warns at the same value): 0.67 at S = 1000, 0.7 from S ≈ 2200.
    From 10 draws down the formula is ≤ 0: 0, no weights are trusted."""
    if samples <= 10:
        return 0.0
    return min(1.0 - 1.0 / np.log10(samples), PARETO_K_LIMIT)


def limit_text(limit: float) -> str:
    """A k̂ limit in words: three significant digits (0.7, 0.667), so that no row below the
    limit reads as above it at the precision shown."""
    return f"{limit:.3g}"


FORCED = "forced past a plausibility check: "
IMPLAUSIBLE = "implausible answer: "
FACT = "Of note: "
NAMED_ROWS = 5  # rows with a high Pareto k named in the verdict (all in summary.json)


@dataclass(frozen=True)
class Verdict:
    """What a run's reader must know before trusting it.

    Attributes:
        lines: every check that failed, one line each, most serious first (empty: all pass).
    """

    lines: tuple[str, ...] = ()
    facts: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        """True when every check passed (facts are no failures)."""
        return not self.lines

    @property
    def text(self) -> str:
        """The verdict in one line (``verdict: …`` on stdout, the report's verdict box)."""
        checks = "; ".join(self.lines) if self.lines else ALL_PASS
        return checks + (f". {FACT}" + "; ".join(self.facts) if self.facts else "")

    def as_json(self) -> dict[str, Any]:
        return {
            "ok": self.ok,
            "lines": list(self.lines),
            "facts": list(self.facts),
            "text": self.text,
        }

    @classmethod
    def from_json(cls, payload: dict[str, Any]) -> Verdict:
        return cls(tuple(payload["lines"]), tuple(payload.get("facts", ())))


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
        named = summary["predictive"].get("pareto_k_rows") or []
        words = [row_words(row) for row in named[:NAMED_ROWS]]
        if len(named) > NAMED_ROWS:
            words.append(f"{len(named) - NAMED_ROWS} more in summary.json")
        where = ": " + "; ".join(words) if words else ""
        lines.append(
            f"{bad} measurement(s) with Pareto k > {limit_text(_loo_limit(summary))} "
            f"(PSIS-LOO unreliable there){where}"
        )
    return Verdict(tuple(lines), tuple(answer_facts(summary)))


def row_words(row: dict[str, Any]) -> str:
    """One measurement row in words: series, sample, angles [deg] and its Pareto k."""
    phi = row.get("phi_s_deg")
    where = "" if phi is None else f", φs {phi:g}°"
    return (
        f"series {row['series']}, sample {row['sample']}, θi {row['theta_i_deg']:g}°, "
        f"θs {row['theta_s_deg']:g}°{where} (k {row['k']:.2f})"
    )


QUANTITY_WORDS = {"pi_brdf0": "π·BRDF0", "brdf0": "BRDF0"}
HEADLINE = ("tis_70deg", "pi_brdf0")  # the headline widths whose carriers the verdict names
SHARE_STATED = 1.0 / 3.0  # an assumption carrying more of a headline width is named


def carried_shares(
    width: dict[str, Any], quantities: Sequence[str], least: float = SHARE_STATED
) -> list[tuple[str, str, float]]:
    """(quantity, the assumption in words, share) for each assumption of the error model
    that alone carries more than ``least`` of a quantity's 95 % width (share = 1 − the
    width ratio without it, :mod:`brdf_infer.posterior._width`), largest first."""
    found = []
    for quantity in quantities:
        for entry in width.get(quantity, {}).get("without", {}).values():
            if entry["ratio"] is None:  # unreliable: no interval without it
                continue
            share = 1.0 - entry["ratio"]
            if share > least:
                found.append((quantity, entry["words"], float(share)))
    return sorted(found, key=lambda item: -item[2])


def quantity_words(name: str) -> str:
    """A headline quantity or parameter's name in words (``tis_70deg`` → ``TIS(70°)``)."""
    if name.startswith("tis_") and name.endswith("deg"):
        return f"TIS({name[4:-3]}°)"
    return QUANTITY_WORDS.get(name, name)


def value_words(name: str, value: float) -> str:
    """A value of a quantity with its unit (fractions in %)."""
    if name.startswith("tis_") or name == "pi_brdf0":
        return f"{100 * value:.3g} %"
    if name == "brdf0":
        return f"{value:.3g} sr⁻¹"
    return f"{value:.3g}"


def answer_facts(summary: PosteriorSummary) -> list[str]:
    """The facts of the verdict (module docstring) from the run's ``table``, ``width``,
    ``learned`` and ``reference`` records (a run written before they existed has none)."""
    carried: dict[str, list[str]] = {}
    for quantity, words, share in carried_shares(summary.get("width", {}), HEADLINE):
        carried.setdefault(words, []).append(f"{100 * share:.0f} % of {quantity_words(quantity)}'s")
    facts = table_facts(summary.get("table"))
    facts += [
        f"{words} assumption alone carries {' and '.join(parts)} 95 % width"
        for words, parts in carried.items()
    ]
    for name in ("sample_sd", "repeatability"):
        entry = summary.get("learned", {}).get(name)
        if entry is not None and not entry["learned"]:
            facts.append(
                f"the {NOISE_WORDS[name]} is {entry['words']}: the data do not contract it "
                f"(contraction {entry['contraction']:.2f})"
            )
    outside = [
        f"{quantity_words(r['quantity'])} {value_words(r['quantity'], r['value'])} (posterior "
        f"quantile {r['posterior_quantile']:.3f})"
        for r in summary.get("reference", [])
        if not r["inside95"]
    ]
    if outside:
        facts.append(
            "reference values outside the 95 % interval: "
            + ", ".join(outside)
            + ' (docs/instruments.md, "The answer and the article")'
        )
    refitted = summary.get("predictive", {}).get("loo_refit_rows") or []
    if refitted:
        facts.append(
            f"{len(refitted)} influential measurement(s), Pareto k > "
            f"{limit_text(_loo_limit(summary))}, their leave-one-out terms from a refit without "
            "them: " + "; ".join(row_words(row) for row in refitted)
        )
    return facts


def _loo_limit(summary: PosteriorSummary) -> float:
    """The Pareto k̂ limit the run's PSIS-LOO was judged by (runs before it: 0.7)."""
    return summary.get("predictive", {}).get("pareto_k_limit", PARETO_K_LIMIT)


NOISE_WORDS = {"sample_sd": "sample-to-sample scale", "repeatability": "repeatability"}
