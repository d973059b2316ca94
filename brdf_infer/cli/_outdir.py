"""Output folders are checked before any work and held by one writer while it writes
(:mod:`brdf_infer._internal.outlock`); a folder created for a command that then writes nothing (bad
input) is removed again."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

from brdf_infer._internal.outlock import writing
from brdf_infer.errors import BadInputError


def check_output_dir(path: str | Path, option: str = "out") -> Path:
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


def claim_output_dir(
    path: str | Path, command: str, claims: contextlib.ExitStack, option: str = "out"
) -> Path:
    """:func:`check_output_dir`, then hold ``path`` for ``command`` until ``claims`` closes
    (the folder is created for the lock; one writer per folder,
    :mod:`brdf_infer._internal.outlock`).

    Raises:
        BadInputError: as :func:`check_output_dir`, or another process writes ``path``.
    """
    path = check_output_dir(path, option)
    claims.enter_context(writing(path, command, option=option))
    return path
