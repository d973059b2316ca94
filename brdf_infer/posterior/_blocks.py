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
KEY_VALUES = 4096  # largest site per draw that tells draws apart (distinct_draws)


def draw_blocks(count: int, rows: int, columns: int) -> int:
    """Draws per block when a computation holds ``columns`` values per row and draw
    (:data:`CHUNK_VALUES` at most; every draw at once where they fit)."""
    return int(max(1, min(count, CHUNK_VALUES // max(1, rows * columns))))


def factor_columns(noise) -> int:
    """Columns of the likelihood's low-rank factor W (samples, calibration groups, rotation
    settings with two or more rows) of a :class:`~brdf_infer.model.error_model.NoiseLayout`."""
    names = ("sample_members", "calibration_members", "rotation_members")
    return sum(int(np.shape(getattr(noise, name))[-1]) for name in names if hasattr(noise, name))


def distinct_draws(
    flat: dict[str, np.ndarray],
) -> tuple[dict[str, np.ndarray], np.ndarray | None]:
    """The distinct draws of ``flat`` and each draw's index among them (None, and ``flat``
    itself, when no draw repeats). Draws are compared on every site of at most
    :data:`KEY_VALUES` values a draw (the parameters and noise scales; a site of a value per
    row is a function of them): a Laplace run's resampled draws repeat, as a NUTS draw
    repeats the last where a trajectory is rejected."""
    count = len(next(iter(flat.values())))
    keys = [
        np.asarray(values, np.float64).reshape(count, -1)
        for values in flat.values()
        if np.size(values) <= KEY_VALUES * count
    ]
    if count < 2 or not keys:
        return flat, None
    _, first, inverse = np.unique(
        np.concatenate(keys, axis=1), axis=0, return_index=True, return_inverse=True
    )
    if first.size == count:
        return flat, None
    return {name: np.asarray(values)[first] for name, values in flat.items()}, inverse.reshape(-1)


def over_draw_blocks(
    compute: Callable[[dict[str, np.ndarray]], tuple],
    flat: dict[str, np.ndarray],
    rows: int,
    columns: int,
    dtype=np.float64,
) -> list[np.ndarray]:
    """``compute`` of every draw of ``flat`` (sites with the draws on the leading axis), a
    block of :func:`draw_blocks` draws at a time; ``compute`` returns a tuple of arrays whose
    leading axis is the block's draws, and depends on nothing but them. A draw that repeats
    another (:func:`distinct_draws`) is computed once. Returns those arrays for every draw, as
    ``dtype``."""
    count = len(next(iter(flat.values())))
    distinct, inverse = distinct_draws(flat)
    if inverse is not None:  # repeated draws (resampled or rejected): each computed once
        outputs = over_draw_blocks(compute, distinct, rows, columns, dtype)
        return [output[inverse] for output in outputs]
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
