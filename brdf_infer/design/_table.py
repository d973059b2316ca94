"""The chosen settings of ``design.json`` as a table (the command line's and the report's)."""

from __future__ import annotations

DESIGN_HEADERS = ["step", "θi [deg]", "θs [deg]", "series", "expected sd", "sd ratio", "EIG [nats]"]


def design_rows(payload: dict) -> list[list[str]]:
    """One row per chosen setting, in the order chosen."""
    return [
        [
            str(c["step"]),
            f"{c['theta_i_deg']:g}",
            f"{c['theta_s_deg']:g}",
            c["series"],
            f"{c['expected_sd']:.3g}",
            f"{c['sd_ratio']:.3f}",
            f"{c['eig_nats']:.2f}",
        ]
        for c in payload["chosen"]
    ]
