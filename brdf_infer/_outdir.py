"""Output folders are checked before any work and created only when results are written."""

from __future__ import annotations

import os
from pathlib import Path

from brdf_infer.errors import BadInputError


def check_output_dir(path: str | Path, option: str = "--out") -> Path:
    """``path`` if a results folder can be written there; nothing is created.

    Raises:
        BadInputError: ``path`` is a file, or neither it nor the nearest existing folder above
            it is writable.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise BadInputError("exists and is not a folder", file=path, field=option)
    existing = path
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir() or not os.access(existing, os.W_OK | os.X_OK):
        raise BadInputError(
            f"cannot write here ({existing} is not writable)", file=path, field=option
        )
    return path
