"""Report section "Where to measure next" from a run folder's ``design.json``."""

from __future__ import annotations

from brdf_infer.design import DESIGN_HEADERS, current_words, design_rows, reach_line
from brdf_infer.report import _html
from brdf_infer.runs.folder import DESIGN_FIGURE, RunFolder


def design_section(run: RunFolder) -> list[str]:
    """The report's section from ``run/design.json`` (none when the run has none); the map is
    the study's own ``design.png`` (the report computes nothing)."""
    payload = run.design()
    if payload is None:
        return []
    current = current_words(payload)
    today = "" if current is None else f" Today: {current}."
    session = payload.get("same_session")
    session = (
        f"each row continuing series {session}'s session (its reference measurement)"
        if session
        else "each round of rows a new session, with a reference measurement of its own"
    )
    reach = reach_line(payload)
    reach = f" The instrument's {reach}." if reach else ""
    parts = [
        "<h2>Where to measure next</h2>",
        f"<p>The settings that, measured together, are expected to shrink "
        f"{_html.escape(payload.get('target_label', payload['target']))} most "
        f"(budget {payload['budget']}; {session}; each row's predictive given the rows "
        f"measured so far, by importance reweighting of the posterior draws; "
        f"<code>design.json</code> lists every candidate).{today}{_html.escape(reach)}</p>",
        _html.table(DESIGN_HEADERS, design_rows(payload)),
    ]
    figure = run.file(DESIGN_FIGURE)
    if figure.is_file():
        parts.append(
            _html.figure(
                figure.read_bytes(),
                "Expected sd ratio after one more row at each reachable setting; measured rows "
                "and the chosen settings (numbered, in the order chosen) marked.",
            )
        )
    return parts
