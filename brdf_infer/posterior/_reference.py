"""A scene's published reference values placed in the posterior (``[reference]``).

Each value gets its posterior quantile — the share of draws below it — with its Monte Carlo
standard error √(q (1 − q) / ESS) (ESS: of the indicator of a draw below the value, across the
chains), and a place: ``inside`` the central 95 % interval (the quantile within 0.025–0.975 by
more than :data:`EDGE_SE` standard errors), ``outside`` (beyond it by as much), else ``at the
edge``: a cut within the Monte Carlo error of the quantile is called neither (the same article
quantity, π·BRDF0 3.6 % and BRDF0 1.14·10⁻² sr⁻¹, fell either side of 0.025 by chance). A
value outside says that this run and the publication disagree, not which is right: the two
differ in what they assume (docs/instruments.md, "The answer and the article").
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from brdf_infer._internal import arviz as az
from brdf_infer.scene import ReferenceValue


def posterior_quantile(draws: np.ndarray, value: float) -> float:
    """The share of ``draws`` below ``value`` (ties count half)."""
    draws = np.asarray(draws, float).reshape(-1)
    return float(np.mean(draws < value) + 0.5 * np.mean(draws == value))


EDGE_SE = 2.0  # standard errors of the quantile between "inside"/"outside" and the cut


def quantile_place(quantile: float, mcse: float) -> str:
    """``inside``, ``outside`` or ``at the edge`` of the central 95 % interval (module
    docstring)."""
    margin = EDGE_SE * mcse
    if 0.025 + margin <= quantile <= 0.975 - margin:
        return "inside"
    if quantile < 0.025 - margin or quantile > 0.975 + margin:
        return "outside"
    return "at the edge"


def reference_record(
    references: Sequence[ReferenceValue], draws: dict[str, np.ndarray], chains: int = 1
) -> list[dict[str, Any]]:
    """The ``"reference"`` record of a run: one entry per reference value whose quantity the
    run has draws of (``draws``: headline quantities and physical parameters, flattened, of
    ``chains`` chains).

    Returns:
        ``[{"quantity", "value", "source", "posterior_quantile", "quantile_mcse", "place",
        "inside95"}]`` (``inside95``: ``place`` is ``inside``).
    """
    record = []
    for reference in references:
        if reference.quantity not in draws:
            continue
        values = np.asarray(draws[reference.quantity], float)
        quantile = posterior_quantile(values, reference.value)
        rows = chains if values.size % chains == 0 else 1  # draws spaced over all chains: one
        below = np.reshape(values < reference.value, (rows, -1)).astype(float)
        ess = float(az.ess(below)) if 0.0 < quantile < 1.0 else float(values.size)
        mcse = float(np.sqrt(quantile * (1.0 - quantile) / max(ess, 1.0)))
        place = quantile_place(quantile, mcse)
        record.append(
            {
                "quantity": reference.quantity,
                "value": reference.value,
                "source": reference.source,
                "posterior_quantile": quantile,
                "quantile_mcse": mcse,
                "place": place,
                "inside95": place == "inside",
            }
        )
    return record
