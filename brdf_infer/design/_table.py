"""The chosen settings of ``design.json`` as a table (the command line's and the report's)."""

from __future__ import annotations

DESIGN_HEADERS = ["step", "θi [deg]", "θs [deg]", "series", "expected sd", "sd ratio", "EIG [nats]"]


def target_scale(payload: dict) -> tuple[float, str]:
    """(factor, unit) in which to show the target: TIS and π·BRDF0 in per cent, the rest as
    they are in ``design.json``."""
    target = payload["target"]
    return (100.0, " %") if target.startswith("tis") or target == "pi_brdf0" else (1.0, "")


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
            f"{scale * c['expected_sd']:.3g}{unit}",
            f"{c['sd_ratio']:.3f}",
            f"{c['eig_nats']:.2f}",
        ]
        for c in payload["chosen"]
    ]
