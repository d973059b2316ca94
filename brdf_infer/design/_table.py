"""The chosen settings of ``design.json`` as a table (the command line's and the report's)."""

from __future__ import annotations

DESIGN_HEADERS = [
    "step",
    "θi [deg]",
    "θs [deg]",
    "series",
    "session",
    "expected sd",
    "sd ratio",
    "EIG [nats]",
]


def target_scale(payload: dict) -> tuple[float, str]:
    """(factor, unit) in which to show the target: TIS and π·BRDF0 in per cent, the rest as
    they are in ``design.json``."""
    target = payload["target"]
    return (100.0, " %") if target.startswith("tis") or target == "pi_brdf0" else (1.0, "")


def current_words(payload: dict) -> str | None:
    """The target today in its unit (:func:`target_scale`): median, 95 % interval and sd, as
    the command line and the report print it (None: a design.json without the current
    posterior's numbers)."""
    current = payload["current"]
    if current.get("median") is None:
        return None
    k, unit = target_scale(payload)
    return (
        f"{k * current['median']:.4g}{unit} ({k * current['lo95']:.4g}–"
        f"{k * current['hi95']:.4g}{unit}, 95 %), sd {k * current['sd']:.3g}{unit}"
    )


def design_rows(payload: dict) -> list[list[str]]:
    """One row per chosen setting, in the order chosen (the expected sd in the target's
    unit, :func:`target_scale`)."""
    scale, unit = target_scale(payload)
    return [
        [
            str(c["step"]),
            f"{c['theta_i_deg']:g}",
            f"{c['theta_s_deg']:g}",
            c["series"],
            c.get("session", c["series"]),  # design.json before sessions: the series' own
            f"{scale * c['expected_sd']:.3g}{unit}",
            f"{c['sd_ratio']:.3f}",
            f"{c['eig_nats']:.2f}",
        ]
        for c in payload["chosen"]
    ]


def reach_line(payload: dict) -> str:
    """What the instrument reaches and how many grid settings were left out, and why (empty
    for a design.json without it)."""
    reach, left = payload.get("reach"), payload.get("left_out")
    if not reach:
        return ""
    low_i, high_i = reach["theta_i_deg"]
    low_s, high_s = reach["theta_s_deg"]
    text = (
        f"reachable: θi {low_i:g}–{high_i:g}°, θs {low_s:g}–{high_s:g}°, camera ≥ "
        f"{reach['source_clearance_deg']:g}° from the beam"
    )
    if not left:
        return text + " (candidates from a file, each checked)"
    out = left["grid"] - left["reachable"]
    measured = (
        f"; {left['measured']} reachable ones already measured in the session continued"
        if left.get("measured")
        else ""
    )
    return (
        f"{text}; of {left['grid']} grid settings {out} left out: θi out of range "
        f"{left['theta_i_deg']}, θs out of range {left['theta_s_deg']}, camera too near the "
        f"beam {left['source_clearance_deg']}{measured}"
    )
