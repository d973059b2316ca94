"""Atomic file writes: a temporary file beside the target, then ``os.replace``.

A failed write (a full disk, a read-only folder, a file-size limit) leaves the target as it was
and no temporary file, and raises :class:`OSError` naming the target (one line, exit 2, on the
command line). A temporary file a killed writer left (``.NAME.XXXXXXXX.tmp``, 8 hexadecimal
characters) goes with the folder's next writer (:mod:`brdf_infer._internal.outlock`). It is
created with mode ``0o666``, narrowed by the umask as any new file, so the published file has
the permissions of a plain ``open(path, "w")`` (the umask, process-wide, is never set).
"""

from __future__ import annotations

import contextlib
import json
import os
import secrets
from pathlib import Path
from typing import Any


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` so that readers see the old file or the whole new one.

    Raises:
        OSError: the write failed, as ``cannot write: <why>`` naming ``path``; ``path`` is
            unchanged.
    """
    path = Path(path)
    temporary = path.parent / f".{path.name}.{secrets.token_hex(4)}.tmp"
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
        with os.fdopen(os.open(temporary, flags, 0o666), "wb") as stream:
            stream.write(data)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(temporary, path)
    except BaseException as error:
        with contextlib.suppress(OSError):
            temporary.unlink()
        if not isinstance(error, OSError) or error.filename == str(path):
            raise
        what = error.strerror or str(error)
        raise OSError(error.errno, f"cannot write: {what}", str(path)) from error
    return path


def atomic_write_json(path: str | Path, content: Any) -> Path:
    """Atomically write ``content`` as indented JSON."""
    return atomic_write_bytes(path, (json.dumps(content, indent=2) + "\n").encode())
