"""A scene's published reference values placed in the posterior (``[reference]``).

Each value gets its posterior quantile — the share of draws below it — and whether it lies
inside the central 95 % interval (quantile within 0.025–0.975). A value outside says that this
run and the publication disagree, not which is right: the two differ in what they assume
(docs/instruments.md, "The answer and the article").
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from brdf_infer.scene import ReferenceValue


def posterior_quantile(draws: np.ndarray, value: float) -> float:
    """The share of ``draws`` below ``value`` (ties count half)."""
    draws = np.asarray(draws, float).reshape(-1)
    return float(np.mean(draws < value) + 0.5 * np.mean(draws == value))


def reference_record(
    references: Sequence[ReferenceValue], draws: dict[str, np.ndarray]
) -> list[dict[str, Any]]:
    """The ``"reference"`` record of a run: one entry per reference value whose quantity the
    run has draws of (``draws``: headline quantities and physical parameters, flattened).

    Returns:
        ``[{"quantity", "value", "source", "posterior_quantile", "inside95"}]``.
    """
    record = []
    for reference in references:
        if reference.quantity not in draws:
            continue
        quantile = posterior_quantile(draws[reference.quantity], reference.value)
        record.append(
            {
                "quantity": reference.quantity,
                "value": reference.value,
                "source": reference.source,
                "posterior_quantile": quantile,
                "inside95": bool(0.025 <= quantile <= 0.975),
            }
        )
    return record
