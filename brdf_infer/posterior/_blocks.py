"""Work over every posterior draw a block of draws at a time.

The likelihood's parts of one draw hold rows × (columns of the low-rank factor + a few)
values; for a whole instrument table (6 × 10⁴ rows) and 4000 draws that is tens of GB at
once. Here a function of the draws runs on blocks of at most :data:`CHUNK_VALUES` such
values, the last block padded with the last draw to the others' shape, so that one compiled
program serves every block; a small run is one block, as before.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

CHUNK_VALUES = 2**24  # likelihood-part values of one block of draws (128 MiB of float64)


def draw_blocks(count: int, rows: int, columns: int) -> int:
    """Draws per block when a computation holds ``columns`` values per row and draw
    (:data:`CHUNK_VALUES` at most; every draw at once where they fit)."""
    return int(max(1, min(count, CHUNK_VALUES // max(1, rows * columns))))


def factor_columns(noise) -> int:
    """Columns of the likelihood's low-rank factor W (samples, calibration groups, rotation
    settings with two or more rows) of a :class:`~brdf_infer.model.error_model.NoiseLayout`."""
    names = ("sample_members", "calibration_members", "rotation_members")
    return sum(int(np.shape(getattr(noise, name))[-1]) for name in names if hasattr(noise, name))


def over_draw_blocks(
    compute: Callable[[dict[str, np.ndarray]], tuple],
    flat: dict[str, np.ndarray],
    rows: int,
    columns: int,
    dtype=np.float64,
) -> list[np.ndarray]:
    """``compute`` of every draw of ``flat`` (sites with the draws on the leading axis), a
    block of :func:`draw_blocks` draws at a time; ``compute`` returns a tuple of arrays whose
    leading axis is the block's draws. Returns those arrays for every draw, as ``dtype``."""
    count = len(next(iter(flat.values())))
    size = draw_blocks(count, rows, 4 + columns)
    results: list[np.ndarray] | None = None
    for start in range(0, count, size):
        index = np.minimum(np.arange(start, start + size), count - 1)  # padded with the last
        outputs = compute({name: values[index] for name, values in flat.items()})
        kept = min(size, count - start)
        if results is None:
            results = [np.empty((count, *np.shape(out)[1:]), dtype) for out in outputs]
        for result, out in zip(results, outputs, strict=True):
            result[start : start + kept] = np.asarray(out)[:kept]
    return results or []
