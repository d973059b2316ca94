"""Atomic file writes: write a temporary file beside the target, then ``os.replace``.

A write that fails (a full disk, a read-only folder, a file-size limit) leaves the target as
it was and no temporary file, and raises :class:`OSError` naming the target, so that the
command line says which file could not be written (one line, exit 2).
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from brdf_infer._outlock import note_written


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` so that readers see the old file or the whole new one.

    Raises:
        OSError: the write failed (:func:`_failed_write`); ``path`` is unchanged.
    """
    path = Path(path)
    with _failed_write(path):
        path.parent.mkdir(parents=True, exist_ok=True)
        handle, temporary = tempfile.mkstemp(
            dir=path.parent, prefix=f".{path.name}.", suffix=".tmp"
        )
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


def publish(temporary: str | Path, path: str | Path) -> None:
    """Give ``temporary`` the permissions of a normally created file, then rename it."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(temporary, 0o666 & ~umask)
    os.replace(temporary, path)
    note_written(path)


def atomic_write_json(path: str | Path, content: Any) -> Path:
    """Atomically write ``content`` as indented JSON."""
    return atomic_write_bytes(path, (json.dumps(content, indent=2) + "\n").encode())
