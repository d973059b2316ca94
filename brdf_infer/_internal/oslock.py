"""The advisory lock under :mod:`brdf_infer._internal.outlock`, on every platform.

``outlock`` keeps one lock file per results folder, holding the writer's record (JSON with
its process id and host); this module says whether a process holds that file. Which way is
chosen once, at import (``BACKEND``):

- ``"flock"`` (Linux, macOS, the BSDs): ``fcntl.flock`` on the open file. The kernel releases
  the lock when its process dies, however it dies.
- ``"msvcrt"`` (Windows): ``msvcrt.locking`` of one byte far past the record, which leaves the
  record readable by others; released by Windows when the process dies. No shared mode: a
  reader probing the file takes it exclusively for a moment.
- ``"record"`` (a platform with neither): the record stands for the lock: the file is held
  while the process it names is alive on this host and has not marked its write stopped. A
  record naming another host is taken as held (its process cannot be checked from here). Two
  processes taking over the same dead writer's folder at the same moment may both succeed:
  the flock and msvcrt locks do not have that hole.

A file system without locks (``ENOLCK`` and the like, some network mounts) is written without
one, as before.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import socket
import time

try:
    import fcntl
except ImportError:  # Windows, or a platform without it
    fcntl = None
try:
    import msvcrt
except ImportError:
    msvcrt = None

BACKEND = "flock" if fcntl is not None else "msvcrt" if msvcrt is not None else "record"
_NO_LOCKING = {errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL}
_FAR = 2**30  # msvcrt: the locked byte, past any record (locking past the end is allowed)
_FRESH_SECONDS = 10.0  # record: an empty file this young is a writer about to write its record


def try_lock(fd: int, exclusive: bool, created: bool = False) -> bool:
    """Take the lock of the open lock file ``fd`` without waiting (``created``: this process
    just created the file). False when another process holds it.

    Raises:
        OSError: the lock could not be taken for another reason than a holder.
    """
    if BACKEND == "record":
        return created or not _record_held(fd)
    try:
        if BACKEND == "flock":
            fcntl.flock(fd, (fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH) | fcntl.LOCK_NB)
        else:
            os.lseek(fd, _FAR, os.SEEK_SET)
            msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
    except (BlockingIOError, PermissionError):
        return False
    except OSError as error:
        if error.errno in _NO_LOCKING:
            return True  # a file system without locks: written without the lock
        if error.errno in {errno.EACCES, errno.EDEADLK}:  # msvcrt: held by another
            return False
        raise
    return True


def unlock(fd: int) -> None:
    """Release the lock of ``fd`` taken by :func:`try_lock` (closing ``fd`` releases it too)."""
    if BACKEND == "flock":
        fcntl.flock(fd, fcntl.LOCK_UN)
    elif BACKEND == "msvcrt":
        os.lseek(fd, _FAR, os.SEEK_SET)
        with contextlib.suppress(OSError):
            msvcrt.locking(fd, msvcrt.LK_UNLCK, 1)


def _record_held(fd: int) -> bool:
    """The record in ``fd`` names a writer that is still writing (backend ``record``)."""
    os.lseek(fd, 0, os.SEEK_SET)
    text = os.read(fd, 1 << 16).decode("utf-8", "replace")
    if not text.strip():
        return time.time() - os.fstat(fd).st_mtime < _FRESH_SECONDS
    try:
        record = json.loads(text)
        pid, host, stopped = int(record["pid"]), record.get("host"), record.get("stopped")
    except (ValueError, TypeError, KeyError, AttributeError):
        return False  # unreadable: its writer is gone
    if stopped is not None or pid == os.getpid():
        return False  # it said it stopped, or it was this process (its claim has ended)
    if host != socket.gethostname():
        return True
    return _alive(pid)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # another user's process
    except OSError:
        return False
    return True
