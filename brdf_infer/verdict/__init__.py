"""The verdict of a posterior run: one record, computed once when the run completes.

Written into the run's ``summary.json`` (``"verdict"``), printed by ``posterior``, ``run`` and
``report`` and rendered by the report as it stands, so that stdout and the report cannot
disagree. It lists, most serious first:

0. the model check: where the data reject the model (the least-squares fit's checks, the
   leave-one-out predictive's uniformity and trends, a parameter piled at a bound;
   :mod:`brdf_infer.posterior`), what they found and what to try next, first: every band is
   conditional on the model;
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
    lines = model_lines(summary.get("model_check"))
    lines += [FORCED + line for line in forced]
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


MISFIT = "the model does not follow the data: "


def model_lines(record: dict[str, Any] | None) -> list[str]:
    """The verdict's first line where the run's model check failed (the data reject the
    model, :mod:`brdf_infer.posterior`): the failed checks in words, that the bands are
    conditional on the model, and what to try next; none where it passed (or a run written
    before the record)."""
    if record is None or record["ok"]:
        return []
    found = "; ".join(entry["words"] for entry in record["checks"] if not entry["ok"])
    after = record.get("next") or []
    step = f". Next: {'; or '.join(after)}" if after else ""
    return [f"{MISFIT}{found}; every band is conditional on it{step}"]


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
SHARE_STATED = 1.0 / 3.0  # an assumption carrying more of a headline variance is named
ELPD_SE_MULTIPLE = 2.0  # |Δelpd| within this many standard errors: the data cannot tell


def carried_shares(
    width: dict[str, Any],
    quantities: Sequence[str],
    least: float = SHARE_STATED,
    skip: Sequence[str] = (),
) -> list[tuple[str, str, float]]:
    """(quantity, the assumption in words, variance share) for each assumption that carries
    more than ``least`` of a quantity's 95 % interval's variance (1 − (width without it /
    width)², sources adding in quadrature; :mod:`brdf_infer.posterior`'s ``"width"`` record),
    largest first; ``skip``: assumptions (the record's names) left out. A run written before
    the variance share: none."""
    found = []
    for quantity in quantities:
        for name, entry in width.get(quantity, {}).get("without", {}).items():
            if name in skip:
                continue
            share = entry.get("variance_share")
            if share is not None and share > least:
                found.append((quantity, entry["words"], float(share)))
    return sorted(found, key=lambda item: -item[2])


def elpd_words(entry: dict[str, Any]) -> str:
    """The data's judgement of an alternative in words, from its Δelpd (alternative − run)
    and standard error; empty where not computed."""
    delta, se = entry.get("delta_elpd"), entry.get("delta_elpd_se")
    if delta is None or se is None:
        return ""
    value = f"Δelpd {delta:+.1f} ± {se:.1f}"
    if abs(delta) <= ELPD_SE_MULTIPLE * se:
        return f"the data cannot tell them apart ({value})"
    if delta < 0:
        return f"the data prefer the run's model ({value})"
    return f"the data prefer the alternative ({value})"


def alternative_words(entry: dict[str, Any], quantity: str) -> str:
    """One alternative of a headline interval in words (the ``"width"`` record's ``without``
    entry): its variance share where it narrows the interval, else the interval without it
    and that it is wider; with Monte Carlo errors and the data's judgement."""
    name = entry["words"].removeprefix("the ")
    if entry.get("lo95") is None:
        k_hat = entry["pareto_k"]
        return f"{name}: no interval without it (reweighting unreliable, Pareto k {k_hat:.2f})"
    interval = f"{value_words(quantity, entry['lo95'])}–{value_words(quantity, entry['hi95'])}"
    judged = elpd_words(entry)
    judged = f"; {judged}" if judged else ""
    share = entry.get("variance_share")
    if share is not None:
        error = entry.get("variance_share_mcse") or 0.0
        return (
            f"{name} {100 * share:.0f} ± {100 * error:.0f} % of the variance (without it "
            f"{interval}{judged})"
        )
    return f"without {name} wider, {interval} (no share of this width{judged})"


def width_words(width: dict[str, Any] | None, quantity: str) -> str:
    """What carries one headline interval, in one line: each alternative
    (:func:`alternative_words`, largest variance share first) and the prior predictive
    interval."""
    if not width:
        return "not recorded (a run written before this record)"
    entries = sorted(width["without"].values(), key=lambda e: -(e.get("variance_share") or -1.0))
    parts = [alternative_words(entry, quantity) for entry in entries]
    if "without_note" in width:
        parts.append(width["without_note"])
    prior = width["prior"]
    parts.append(
        f"prior alone {value_words(quantity, prior['lo95'])}–{value_words(quantity, prior['hi95'])}"
    )
    return "; ".join(parts)


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
    target = summary.get("target", "coating")
    carried: dict[str, list[str]] = {}
    whose = "" if target == "coating" else "the coating's "
    # the measured samples' bands are conditional on their own effects: not their width
    skip = ("sample_effect",) if target == "measured" else ()
    for quantity, words, share in carried_shares(summary.get("width", {}), HEADLINE, skip=skip):
        carried.setdefault(words, []).append(
            f"{100 * share:.0f} % of {whose}{quantity_words(quantity)}'s"
        )
    facts = table_facts(summary.get("table"))
    facts += target_facts(summary.get("targets"))
    facts += [
        f"{words} carries {' and '.join(parts)} 95 % interval variance (in quadrature)"
        for words, parts in carried.items()
    ]
    for name in ("sample_sd", "repeatability"):
        entry = summary.get("learned", {}).get(name)
        if entry is not None and not entry["learned"]:
            where = (
                " (it sets the coating's and a new part's bands, not the measured sample's)"
                if name == "sample_sd" and target == "measured"
                else ""
            )
            facts.append(
                f"the {NOISE_WORDS[name]} is {entry['words']}: the data do not contract it "
                f"(contraction {entry['contraction']:.2f}){where}"
            )
    places = []
    for place, where in (("outside", "outside"), ("at the edge", "at the edge of")):
        found = [reference_words(r) for r in summary.get("reference", []) if _place(r) == place]
        if found:
            places.append(f"{where} the 95 % interval: " + ", ".join(found))
    if places:
        facts.append(
            "reference values "
            + "; ".join(places)
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


TARGET_WORDS = {
    "measured": "the sample(s) measured",
    "coating": "the coating (population mean)",
    "new_part": "a new part",
}


def target_facts(targets: dict[str, Any] | None) -> list[str]:
    """Which coating the headline is for (the summary's ``targets``), beside the other two
    targets' TIS(70°) and where τ comes from; none for a run written before the record."""
    if not targets:
        return []
    chosen = targets["chosen"]
    quantity = "tis_70deg" if targets[chosen].get("tis_70deg") else "pi_brdf0"
    if targets[chosen].get(quantity) is None:
        return []

    def interval(name: str) -> str:
        entry = targets[name][quantity]
        return f"{value_words(quantity, entry['lo95'])}–{value_words(quantity, entry['hi95'])}"

    others = ", ".join(
        f"{TARGET_WORDS[name]} {interval(name)}" for name in TARGET_WORDS if name != chosen
    )
    return [
        f"the answer is for {TARGET_WORDS[chosen]}: {quantity_words(quantity)} "
        f"{interval(chosen)} (95 %; {others}; τ: {targets['tau_source']})"
    ]


def _place(reference: dict[str, Any]) -> str:
    """A reference value's place in the 95 % interval (runs before ``place``: from
    ``inside95``)."""
    return reference.get("place", "inside" if reference["inside95"] else "outside")


def reference_words(reference: dict[str, Any]) -> str:
    """A reference value and its posterior quantile (± its Monte Carlo error) in words."""
    quantity = reference["quantity"]
    error = reference.get("quantile_mcse")
    plus = "" if error is None else f" ± {error:.3f}"
    return (
        f"{quantity_words(quantity)} {value_words(quantity, reference['value'])} (posterior "
        f"quantile {reference['posterior_quantile']:.3f}{plus})"
    )


def _loo_limit(summary: PosteriorSummary) -> float:
    """The Pareto k̂ limit the run's PSIS-LOO was judged by (runs before it: 0.7)."""
    return summary.get("predictive", {}).get("pareto_k_limit", PARETO_K_LIMIT)


NOISE_WORDS = {"sample_sd": "sample-to-sample scale", "repeatability": "repeatability"}
