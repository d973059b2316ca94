"""Atomic file writes: write a temporary file beside the target, then ``os.replace``.

A write that fails (a full disk, a read-only folder, a file-size limit) leaves the target as
it was and no temporary file, and raises :class:`OSError` naming the target, so that the
command line says which file could not be written (one line, exit 2).

The temporary file is created with mode ``0o666``, which the process's umask narrows as it
does for any new file, so the published file has the permissions a plain ``open(path, "w")``
would give it (``tempfile.mkstemp`` would create it ``0o600``; reading the umask means setting
it, process-wide and unsafe between threads, so it is never touched).
"""

from __future__ import annotations

import contextlib
import json
import os
import secrets
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from brdf_infer._internal.outlock import note_written


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` so that readers see the old file or the whole new one.

    Raises:
        OSError: the write failed (:func:`_failed_write`); ``path`` is unchanged.
    """
    path = Path(path)
    with _failed_write(path):
        path.parent.mkdir(parents=True, exist_ok=True)
        handle, temporary = _create_temporary(path)
        try:
            with os.fdopen(handle, "wb") as stream:
                stream.write(data)
                stream.flush()
                os.fsync(stream.fileno())
            publish(temporary, path)
        except BaseException:
            Path(temporary).unlink(missing_ok=True)
            raise
    return path


@contextlib.contextmanager
def _failed_write(path: Path) -> Iterator[None]:
    """Re-raise an :class:`OSError` of writing ``path`` as one that names ``path`` and what
    failed (``No space left on device``, ``File too large``, ``Permission denied``)."""
    try:
        yield
    except OSError as error:
        if error.filename == str(path):
            raise
        what = error.strerror or str(error)
        raise OSError(error.errno, f"cannot write: {what}", str(path)) from error


def _create_temporary(path: Path) -> tuple[int, str]:
    """A new file ``.NAME.XXXXXXXX.tmp`` beside ``path``, open for writing, created with mode
    ``0o666`` less the umask (8 random hexadecimal characters, as brdf_infer._internal.outlock's
    clean-up of a dead writer's temporary files expects)."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
    while True:
        temporary = str(path.parent / f".{path.name}.{secrets.token_hex(4)}.tmp")
        try:
            return os.open(temporary, flags, 0o666), temporary
        except FileExistsError:
            continue


def publish(temporary: str | Path, path: str | Path) -> None:
    """Rename the written ``temporary`` (created by :func:`_create_temporary`) to ``path``."""
    os.replace(temporary, path)
    note_written(path)


def atomic_write_json(path: str | Path, content: Any) -> Path:
    """Atomically write ``content`` as indented JSON."""
    return atomic_write_bytes(path, (json.dumps(content, indent=2) + "\n").encode())
