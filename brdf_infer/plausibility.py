"""Plausibility warnings: values that look like the wrong unit (not errors; printed on stderr).

Angles are in degrees, reflectance and TIS are fractions, BRDF is in sr⁻¹. A table whose
angles all lie within ±π/2 was probably written in radians; a reflectance that implies a TIS or
π·BRDF0 above 1 was probably given in percent, or its aperture is wrong.
"""

from __future__ import annotations

import math

import numpy as np

from brdf_infer.measurements import Measurements
from brdf_infer.params import HemisphereConstants, Params


def measurement_warnings(measurements: Measurements) -> list[str]:
    """Warnings about a measurement table whose values look like the wrong unit."""
    warnings = []
    where = str(measurements.path)
    angles = np.abs(np.concatenate([measurements.theta_i_deg, measurements.theta_s_deg]))
    if angles.size and angles.max() <= math.pi / 2 and angles.max() > 0:
        warnings.append(
            f"{where}: every angle lies within ±π/2 (largest {angles.max():.3g}): are they in "
            "radians? brdf_infer reads degrees"
        )
    if measurements.reflectance_err is not None:
        large = np.flatnonzero(measurements.reflectance_err > measurements.reflectance)
        if large.size:
            rows = ", ".join(str(k + 1) for k in large[:5]) + (" ..." if large.size > 5 else "")
            warnings.append(
                f"{where}: {large.size} row(s) have reflectance_err larger than the value "
                f"(rows {rows}): is the σ column in other units than the values?"
            )
    return warnings


def parameter_warnings(
    params: Params,
    theta_i_deg,
    constants: HemisphereConstants,
    what: str = "the fitted parameters",
) -> list[str]:
    """Warnings when ``params`` scatter more than they receive: π·BRDF0 or TIS above 1."""
    from brdf_infer.model import tis

    warnings = []
    if math.pi * float(params.brdf0) > 1:
        warnings.append(
            f"π·BRDF0 = {math.pi * float(params.brdf0):.3g} > 1 at {what}: more light scattered "
            "than received; is the reflectance in percent, or an aperture wrong?"
        )
    angles = np.asarray(theta_i_deg, float)
    values = np.asarray(tis(angles, params, True, constants))
    above = angles[values > 1]
    if above.size:
        listed = ", ".join(f"{a:g}" for a in above)
        warnings.append(
            f"TIS > 1 at θi = {listed} deg at {what}: these parameters are not physical; is "
            "the reflectance in percent, or an aperture wrong?"
        )
    return warnings
