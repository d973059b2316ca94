"""What a posterior run will add to the memory it holds, estimated before it samples, and a
clear refusal when the machine does not have it free (a whole instrument table with every
draw, say).

The estimate adds the parts that grow with rows × draws or rows × chains (the run's other
arrays are a few MiB): the leave-one-out terms of every row and of the draws PSIS-LOO reads
(two arrays, float64 up to 256 MiB each, float32 above;
:func:`~brdf_infer.posterior._results.loo_terms`, ``LOO_VALUES``), one block
of draws' likelihood parts (at most :data:`~brdf_infer.posterior._blocks.CHUNK_VALUES`
values and their temporaries) and the sampler's per-chain gradient intermediates (rows ×
(columns of the low-rank factor + 16) values, eight-fold for reverse mode). The process
itself (the libraries, the compiled programs) is already running when the check is made, so
the memory the machine reports free is what the run has left; the bundled run adds about
0.1 GiB.
"""

from __future__ import annotations

import os

from brdf_infer.errors import BadInputError
from brdf_infer.posterior._blocks import CHUNK_VALUES
from brdf_infer.posterior._results import FLOAT64_TERMS_BYTES, loo_draws

GIB = 2**30


def estimated_bytes(rows: int, draws: int, chains: int, columns: int) -> float:
    """What a posterior run adds to its process's memory at its peak [bytes] (module
    docstring)."""
    kept = chains * loo_draws(draws // chains, rows, chains).size
    width = 8 if kept * rows * 8 <= FLOAT64_TERMS_BYTES else 4
    loo = 2 * kept * rows * width
    block = 4 * min(CHUNK_VALUES, draws * rows * (columns + 4)) * 8
    sampler = 8 * chains * rows * (columns + 16) * 8
    return loo + block + sampler


def available_bytes() -> float | None:
    """Memory this process may still take [bytes]: MemAvailable (Linux), else the physical
    memory, else None (unknown: no check)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return None


def check_memory(rows: int, draws: int, chains: int, columns: int, file=None) -> float:
    """What the run is estimated to add to its memory [bytes], after checking that the
    machine has it free.

    Raises:
        BadInputError: the estimate exceeds the available memory (one line: rows, draws, the
            estimate, what is available and what to change).
    """
    needed = estimated_bytes(rows, draws, chains, columns)
    available = available_bytes()
    if available is not None and needed > available:
        raise BadInputError(
            f"{rows} rows × {draws} draws need about {needed / GIB:.1f} GiB of memory and "
            f"{available / GIB:.1f} GiB is available: thin the table ([bsdf] "
            "keep_every_radial, keep_every_azimuth), use fewer rows, or sample fewer draws "
            "(--chains, --draws)",
            file=file,
        )
    return needed
