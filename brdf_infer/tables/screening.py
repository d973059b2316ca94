"""What reading a scatterometer's table (a tabular .BSDF file) left out, and why: its zero cells
and its dropouts, each counted by a stated rule.

**Zero cells.** A cell above the horizon that holds 0 is read as *below the table's detection
limit* (a scatterometer writes 0 where its detector saw no signal) and left out of the rows:
the lognormal likelihood cannot hold a 0, and a censored term is not in the model. Its count,
and the table's smallest positive value (the detection limit it implies, [sr⁻¹]), are named.
Leaving them out biases the fit upward where the signal is weak (the far tails), so the count
is a fact of the run's verdict. A direction listed more than once counts once, and only when
none of its listings is positive.

**Dropouts.** A dropout is a cell whose detector missed the signal: a value far below every
one of its table neighbours (3.5e-3 among neighbours of 3.6e-2). The rule, per angle of
incidence on the table's own grid (after thinning):

* the neighbours of a cell are the cells one radial step and one azimuth step away that hold a
  positive value above the horizon; a cell with fewer than :data:`MIN_NEIGHBOURS` is not
  judged (a cell at the horizon or a corner of the table);
* its residual is ln v − median(ln v of its neighbours); the table's robust sd s is
  1.4826 · MAD of the residuals of the judged cells of that angle of incidence;
* the cell is a dropout when ln v lies below the *lowest* of its neighbours by more than
  max(:data:`DROPOUT_SDS` · s, ln :data:`DROPOUT_FACTOR`): below a third of every neighbour
  and far outside the table's cell-to-cell scatter.

A smooth slope (a lobe's flank, the fold towards the horizon) always has a neighbour below
the cell, so it is never a dropout; only a local minimum is. Dropouts are left out of the
rows (a factor-10 miss is tens of σ to a lognormal likelihood and would pull the fit), and
each is named (θi, θs, φs, its value and its neighbours' median). Upward spikes are not
judged: a specular glint is physical.

Only a gridded table has neighbours: a CSV's rows are taken as given (a 0 there is refused).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from brdf_infer.runs.records import Dropout, TableRecord

MIN_NEIGHBOURS = 3
DROPOUT_SDS = 5.0
DROPOUT_FACTOR = 3.0
MAD_TO_SD = 1.4826
NAMED_DROPOUTS = 3  # dropouts named in the verdict (all in summary.json)


@dataclass(frozen=True)
class TableScreening:
    """What reading one table left out (module docstring).

    Attributes:
        zero_cells: directions above the horizon whose every listing is 0.
        detection_limit: the table's smallest positive value above the horizon [sr⁻¹].
        below_horizon: positive cells below the horizon (not a BRDF there; left out); a
            cell on it (θ = 90°, outside the model's θ < 90°) is left out uncounted.
        dropouts: each dropout: ``theta_i_deg``, ``theta_s_deg`` (signed in the plane),
            ``phi_s_deg`` (absent in the plane) [deg], ``value`` and ``neighbours`` (their
            median) [sr⁻¹].
        zero_directions: (θi, θ, φ) [deg] of each zero cell, shape (zero_cells, 3): for
            the report's map, not recorded in summary.json.
    """

    zero_cells: int
    detection_limit: float
    below_horizon: int = 0
    dropouts: tuple[Dropout, ...] = ()
    zero_directions: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def as_json(self) -> TableRecord:
        """The record of summary.json's ``"table"``: the counts, the rules in words and every
        dropout."""
        return {
            "zero_cells": self.zero_cells,
            "detection_limit": self.detection_limit,
            "below_horizon": self.below_horizon,
            "dropouts": list(self.dropouts),
            "zero_rule": ZERO_RULE,
            "dropout_rule": DROPOUT_RULE,
        }


ZERO_RULE = "zero cells above the horizon are read as below the detection limit and left out"
DROPOUT_RULE = (
    f"a dropout is a value below 1/{DROPOUT_FACTOR:g} of every one of its ≥ {MIN_NEIGHBOURS} "
    f"table neighbours and more than {DROPOUT_SDS:g} robust sd of the table's neighbour "
    "residuals below the lowest; dropouts are left out"
)


def _neighbour_stack(log_values: np.ndarray) -> np.ndarray:
    """ln v of the four grid neighbours of every cell, NaN where there is none; shape
    (4, n_azimuth, n_radial)."""
    padded = np.pad(log_values, 1, constant_values=np.nan)
    return np.stack(
        [padded[:-2, 1:-1], padded[2:, 1:-1], padded[1:-1, :-2], padded[1:-1, 2:]], axis=0
    )


def dropout_mask(values: np.ndarray, above: np.ndarray) -> np.ndarray:
    """The dropouts of one angle of incidence's table (module docstring).

    Args:
        values: the table [sr⁻¹], shape (n_azimuth, n_radial).
        above: the cells above the horizon, same shape.

    Returns:
        True where a cell is a dropout.
    """
    usable = above & (values > 0.0)
    log_values = np.where(usable, np.log(np.where(usable, values, 1.0)), np.nan)
    neighbours = _neighbour_stack(log_values)
    count = np.sum(np.isfinite(neighbours), axis=0)
    judged = usable & (count >= MIN_NEIGHBOURS)
    if not judged.any():
        return np.zeros(values.shape, bool)
    with np.errstate(all="ignore"):
        residual = log_values - np.nanmedian(np.where(judged, neighbours, 0.0), axis=0)
        lowest = np.nanmin(np.where(judged, neighbours, 0.0), axis=0)
    centred = residual[judged] - np.median(residual[judged])
    spread = MAD_TO_SD * float(np.median(np.abs(centred)))
    margin = max(DROPOUT_SDS * spread, float(np.log(DROPOUT_FACTOR)))
    return judged & (log_values < lowest - margin)


def neighbour_median(values: np.ndarray, above: np.ndarray) -> np.ndarray:
    """The median of each cell's positive neighbours above the horizon [sr⁻¹] (NaN: none)."""
    usable = above & (values > 0.0)
    log_values = np.where(usable, np.log(np.where(usable, values, 1.0)), np.nan)
    neighbours = _neighbour_stack(log_values)
    with warnings.catch_warnings():  # a cell without neighbours: NaN, as documented
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.exp(np.nanmedian(neighbours, axis=0))


def dropout_words(row: Dropout) -> str:
    """One dropout in words: θi, θs (φs) [deg], its value and its neighbours' [sr⁻¹]."""
    phi = row.get("phi_s_deg")
    where = "" if phi is None else f", φs {phi:.4g}°"
    return (
        f"θi {row['theta_i_deg']:g}°, θs {row['theta_s_deg']:.4g}°{where} "
        f"({row['value']:.3g} sr⁻¹ among {row['neighbours']:.3g})"
    )


def table_facts(record: TableRecord | None) -> list[str]:
    """The verdict's facts about the table read (summary.json's ``"table"``): how many rows
    each rule left out; none when no rule touched a row (and for a CSV, which has no such
    record)."""
    if not record:
        return []
    facts = []
    if record["zero_cells"]:
        facts.append(
            f"{record['zero_cells']} zero cell(s) of the .BSDF table left out (read as below "
            f"its detection limit, {record['detection_limit']:.3g} sr⁻¹; the fit is biased up "
            "where they lie)"
        )
    dropouts = record["dropouts"]
    if dropouts:
        named = [dropout_words(row) for row in dropouts[:NAMED_DROPOUTS]]
        if len(dropouts) > NAMED_DROPOUTS:
            named.append(f"{len(dropouts) - NAMED_DROPOUTS} more in summary.json")
        facts.append(
            f"{len(dropouts)} dropout(s) of the .BSDF table left out (below 1/"
            f"{DROPOUT_FACTOR:g} of every neighbour): " + "; ".join(named)
        )
    if record.get("below_horizon"):
        facts.append(
            f"{record['below_horizon']} positive cell(s) of the .BSDF table below the horizon "
            "left out"
        )
    return facts
