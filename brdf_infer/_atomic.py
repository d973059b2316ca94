"""Atomic file writes: write a temporary file beside the target, then ``os.replace``."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

from brdf_infer._outlock import note_written


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` so that readers see the old file or the whole new one."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
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
