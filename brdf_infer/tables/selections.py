"""The paper fit's data selections (Sec. 4.2): which measurement rows enter the regression.

A scene names one (``[paper_fit] selection``, checked when it loads);
:func:`brdf_infer.fit.paper.select_points` applies it. ``paper`` is the one that reproduces
Sec. 5.3.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Selection:
    """Which measurement rows enter the regression.

    Attributes:
        average_samples: replace rows of several samples at one (series, θi, θs) by one row
            holding their mean reflectance (Table 1's "mean reflectance" row).
        drop_repeated_geometry: drop rows whose (θi, θs) an earlier series (in scene order)
            already measured (Table 2's δ = 0 rows repeat Table 1's specular geometry).
        description: what this selection means for the bundled Lyman-α data.
    """

    average_samples: bool
    drop_repeated_geometry: bool
    description: str


SELECTIONS: dict[str, Selection] = {
    "paper": Selection(
        True,
        True,
        "Table 1 as per-angle sample means + Table 2 without its δ = 0 rows (19 points); "
        "reproduces the paper's UV coefficients",
    ),
    "means": Selection(True, False, "Table 1 as per-angle sample means + all of Table 2 (22)"),
    "samples": Selection(False, False, "every sample of Table 1 + all of Table 2 (42 points)"),
    "samples-no-repeats": Selection(
        False, True, "every sample of Table 1 + Table 2 without its δ = 0 rows (39 points)"
    ),
}
