"""Plausibility checks: inputs in the wrong unit and answers that scatter more than they receive.

Angles are in degrees, reflectance and TIS are fractions, BRDF is in sr⁻¹. Four kinds of
value are implausible enough to stop a job before any sampling (unless the user insists with
``--force``, and then the verdict turns red, :mod:`brdf_infer.verdict`):

- **Angles in radians**: every |θi| and |θs| lies within π/2 ≈ 1.571 and there are at least two
  distinct non-zero values (a table in degrees that never leaves ±1.6° of the normal does not
  exist in practice; one non-zero value is too little to tell).
- **Values in percent**: every row of a series implies π·BRDF > 1, through Eq. (6) for raw
  reflectance (R = BRDF·Ω·cos θs) or as it stands for a BRDF series, i.e. the coating is
  brighter than a white diffuser (π·BRDF = 1) in *every* measured direction. A real surface can
  exceed 1/π only near its specular peak; the dimmest row of the bundled Lyman-α series is at
  π·BRDF = 0.048 (I) and 0.073 (II), 100 times less in percent would be 4.8 and 7.3. (A glossy
  sample measured at its specular peak only can pass this line legitimately: ``--force``.)
- **A σ column in percent**: in a series, the median of σ/value (σ: ``reflectance_err`` or
  ``brdf_err``) is above 1, i.e. most of its rows are measured at a signal-to-noise ratio below
  1: the σ is in percent (or relative) rather than in the value's units. A σ of a few percent
  exceeds every raw reflectance (< 1) and every BRDF of a black coating but near a specular
  peak, so the median, not every row, decides; a run on such rows answers nothing (the
  reported BRDF table with its σ in percent sampled 2529 divergent transitions). (A series
  measured mostly below its noise floor can pass this line legitimately: ``--force``.)
- **An answer above 1**: a fit's or a posterior's π·BRDF0 (the near-normal TIS, Sec. 7) or its
  TIS at the scene's incidence angles above 1, more light scattered than received.

Where only some rows have a σ above their value, that is only warned about
(:func:`measurement_warnings`): a faint row can be measured at a signal-to-noise ratio below 1.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from brdf_infer.errors import BadInputError
from brdf_infer.scene import Scene
from brdf_infer.tables.measurements import Measurements

RADIANS_LIMIT = math.pi / 2  # every |angle| within this: radians, not degrees
RADIANS_DISTINCT = 2  # ... with at least this many distinct non-zero values
PERCENT_ROWS = 2  # a series needs this many rows before all of them can look like percent
FORCE_HINT = "insist with --force to go on anyway"


@dataclass(frozen=True)
class Implausible:
    """One failed plausibility check: what is wrong, in which file and field, and what the
    user may have done (the hint)."""

    problem: str
    file: str | None = None
    field: str | None = None
    hint: str = ""

    @property
    def record(self) -> str:
        """The check in one line naming the file and field (what a forced run's verdict
        lists)."""
        return str(BadInputError(self.problem, file=self.file, field=self.field))

    @property
    def message(self) -> str:
        """:attr:`record` with the hint (what a refusal says)."""
        return f"{self.record}; {self.hint}" if self.hint else self.record


def value_field(measurements: Measurements) -> str:
    """The column holding the measured values: ``reflectance`` or ``brdf``."""
    return "reflectance" if measurements.quantity == "raw_reflectance" else "brdf"


def error_field(measurements: Measurements) -> str:
    """The column holding the values' 1σ: ``reflectance_err`` or ``brdf_err``."""
    return f"{value_field(measurements)}_err"


def _value_unit(measurements: Measurements) -> str:
    """The unit of the value column, in words."""
    return "sr^-1" if measurements.quantity == "brdf" else "a fraction"


def _sigma_above(measurements: Measurements) -> np.ndarray:
    """True for the rows whose σ exceeds their value (none without a σ column)."""
    if measurements.reflectance_err is None:
        return np.zeros(len(measurements), bool)
    return measurements.reflectance_err > measurements.reflectance


def _sigma_series(measurements: Measurements) -> dict[str, tuple[int, int, float]]:
    """The series of at least :data:`PERCENT_ROWS` rows whose median σ/value exceeds 1, each
    with (rows whose σ exceeds the value, rows, median σ/value)."""
    if measurements.reflectance_err is None:
        return {}
    ratio = measurements.reflectance_err / measurements.reflectance
    found = {}
    for series in dict.fromkeys(measurements.series.tolist()):
        rows = ratio[measurements.series == series]
        if rows.size >= PERCENT_ROWS and np.median(rows) > 1:
            found[series] = (int((rows > 1).sum()), rows.size, float(np.median(rows)))
    return found


def _sigma_check(measurements: Measurements) -> list[Implausible]:
    """A σ column in percent (module docstring), naming the table's σ column."""
    found = _sigma_series(measurements)
    if not found:
        return []
    field, value = error_field(measurements), value_field(measurements)
    counts = "; ".join(
        f"{above} of {rows} rows of series {name} (median σ/value {median:.3g})"
        for name, (above, rows, median) in found.items()
    )
    return [
        Implausible(
            f"{field} exceeds its value in {counts}: a σ in percent, or relative?",
            str(measurements.path),
            field,
            f"give σ in the units of {value} [{_value_unit(measurements)}]",
        )
    ]


def measurement_checks(scene: Scene, measurements: Measurements) -> list[Implausible]:
    """Angles that look like radians, series whose values look like percent and series whose
    σ looks like percent (module docstring), each naming the measurement file and the column."""
    found = []
    where = str(measurements.path)
    angles = np.abs(np.concatenate([measurements.theta_i_deg, measurements.theta_s_deg]))
    distinct = np.unique(angles[angles > 0])
    if distinct.size >= RADIANS_DISTINCT and distinct.max() <= RADIANS_LIMIT:
        found.append(
            Implausible(
                f"every angle lies within ±π/2 (largest {distinct.max():.3g}): they look like "
                "radians",
                where,
                "theta_i_deg/theta_s_deg",
                "brdf_infer reads degrees",
            )
        )
    pi_brdf = math.pi * np.exp(scene.measured_log_brdf(measurements))
    bright = {}
    for series in dict.fromkeys(measurements.series.tolist()):
        values = pi_brdf[measurements.series == series]
        if values.size >= PERCENT_ROWS and values.min() > 1:
            bright[series] = float(values.min())
    if bright:
        through = " through Eq. (6)" if measurements.quantity == "raw_reflectance" else ""
        found.append(
            Implausible(
                f"every row of series {', '.join(bright)} implies π·BRDF > 1{through} "
                f"(smallest {min(bright.values()):.3g}): the values look like percent",
                where,
                value_field(measurements),
                "brdf_infer reads fractions (π·BRDF = 1 is a white diffuser)",
            )
        )
    return found + _sigma_check(measurements)


def answer_checks(
    what: str,
    theta_i_deg: Sequence[float],
    tis_values: Sequence[float] | None,
    pi_brdf0: float | None = None,
    *,
    file: str | None = None,
    field: str | None = None,
) -> list[Implausible]:
    """π·BRDF0 above 1, or TIS above 1 at any of ``theta_i_deg`` [deg], of an answer (one
    finding naming both where both fail).

    Args:
        what: the answer, in words (e.g. "the least-squares fit").
        theta_i_deg: incidence angles of ``tis_values`` [deg].
        tis_values: TIS [-] at those angles (None: the answer has no TIS).
        pi_brdf0: π·BRDF0 [-] (None: the family has no BRDF0).
        file, field: where the user should look (the measurement file and its value column).
    """
    above = []
    if pi_brdf0 is not None and pi_brdf0 > 1:
        above.append(f"π·BRDF0 = {pi_brdf0:.3g}")
    if tis_values is not None:
        angles = np.asarray(theta_i_deg, float)
        values = np.asarray(tis_values, float)
        if (values > 1).any():
            listed = ", ".join(f"{a:g}" for a in angles[values > 1])
            above.append(f"TIS up to {values.max():.3g} at θi = {listed} deg")
    if not above:
        return []
    return [
        Implausible(
            f"{what} scatters more light than it receives: {' and '.join(above)}, above 1",
            file,
            field,
            "is the reflectance in percent, or an aperture wrong?",
        )
    ]


def fit_checks(scene: Scene, measurements: Measurements, params, what: str) -> list[Implausible]:
    """:func:`answer_checks` of an Eq. (7) parameter set at the scene's incidence angles
    (the TIS only where the scene has the out-of-plane model of Eq. 8)."""
    from brdf_infer.model import tis

    angles = scene.band_theta_i_deg(measurements)
    values = (
        np.asarray(tis(np.asarray(angles, float), params, True, scene.model.constants))
        if scene.model.out_of_plane
        else None
    )
    return answer_checks(
        what,
        angles,
        values,
        math.pi * float(params.brdf0),
        file=str(measurements.path),
        field=value_field(measurements),
    )


def family_fit_checks(
    scene: Scene, measurements: Measurements, member, physical: dict[str, float], what: str
) -> list[Implausible]:
    """:func:`answer_checks` of another family's parameters: its TIS at the scene's angles."""
    angles = scene.band_theta_i_deg(measurements)
    values = np.asarray(member.tis_curve(np.asarray(angles, float), physical))[0]
    return answer_checks(
        what, angles, values, file=str(measurements.path), field=value_field(measurements)
    )


def require_plausible(found: Sequence[Implausible], force: bool) -> None:
    """Stop on the first failed check unless ``force``.

    Raises:
        BadInputError: naming the first check's file and field (and how many more failed).
    """
    if not found or force:
        return
    first = found[0]
    more = f"; {len(found) - 1} more check(s) failed" if len(found) > 1 else ""
    hint = f"; {first.hint}" if first.hint else ""
    raise BadInputError(
        f"{first.problem}{hint}{more} ({FORCE_HINT})", file=first.file, field=first.field
    )


def measurement_warnings(measurements: Measurements) -> list[str]:
    """Warnings (not errors) about a table: rows whose σ exceeds their value, outside the
    series :func:`measurement_checks` finds with their σ in percent."""
    flagged = list(_sigma_series(measurements))
    above = _sigma_above(measurements) & ~np.isin(measurements.series, flagged)
    large = np.flatnonzero(above)
    if not large.size:
        return []
    rows = ", ".join(str(k + 1) for k in large[:5]) + (" ..." if large.size > 5 else "")
    return [
        f"{measurements.path}: {large.size} row(s) have {error_field(measurements)} larger than "
        f"the value (rows {rows}): is the σ column in other units than the "
        f"{value_field(measurements)} values [{_value_unit(measurements)}]?"
    ]


MIRROR_RATIO = 1.5  # the brightest row against its mirrored partner: "brighter"
MIRROR_SHARE = 2.0 / 3.0  # of the groups: "most"
MIRROR_TOLERANCE_DEG = 2.0  # |θs| of a mirrored partner within this


def mirrored_sign_words(measurements: Measurements) -> str | None:
    """Where the rows look recorded with the other θs sign convention, what to check, in one
    line; None otherwise. A black coating scatters forward: in the plane of incidence its
    brightest direction lies at θs > 0 (the specular side, Sec. 4.1), at or beyond the
    specular angle. Among the groups of rows of one series, sample and θi measured on both
    sides of the normal (at least two such groups), when in most (:data:`MIRROR_SHARE`) the
    brightest row lies at θs < 0 and is :data:`MIRROR_RATIO` times its mirrored partner (the
    row at the same |θs| within :data:`MIRROR_TOLERANCE_DEG`), the forward side was probably
    recorded as negative."""
    in_plane = ~measurements.out_of_plane
    keys = list(
        zip(measurements.series, measurements.sample, measurements.theta_i_deg, strict=True)
    )
    groups: dict[tuple, list[int]] = {}
    for row, key in enumerate(keys):
        if in_plane[row]:
            groups.setdefault(tuple(map(str, key)), []).append(row)
    theta_s = np.asarray(measurements.theta_s_deg, float)
    values = np.asarray(measurements.reflectance, float)
    both, backward = 0, 0
    for rows in groups.values():
        rows = np.asarray(rows)
        if not (np.any(theta_s[rows] > 0) and np.any(theta_s[rows] < 0)):
            continue
        both += 1
        brightest = rows[np.argmax(values[rows])]
        if theta_s[brightest] >= 0:
            continue
        partners = rows[np.abs(theta_s[rows] + theta_s[brightest]) <= MIRROR_TOLERANCE_DEG]
        if partners.size and values[brightest] >= MIRROR_RATIO * np.max(values[partners]):
            backward += 1
    if both < 2 or backward < MIRROR_SHARE * both:
        return None
    return (
        f"check the sign convention of theta_s_deg: in {backward} of {both} groups of rows "
        "(series, sample, θi) measured on both sides of the normal the brightest row lies at "
        f"θs < 0, at least {MIRROR_RATIO:g} times its mirrored partner, where a black coating "
        "scatters forward: θs > 0 is the forward side, the specular direction's (Strumik et "
        "al. 2024, Sec. 4.1); if your instrument counts the other way, change the sign of "
        "the column"
    )
