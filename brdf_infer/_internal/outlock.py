"""One writer per results folder, and a folder that says whether it is complete.

A command writing a results folder holds the marker ``.brdf-infer.lock`` in it from before its
first write until its last: JSON naming the writer (process id, host, command, start), under an
``fcntl.flock`` while the writer lives (the kernel drops it however the process ends).

- A second writer is refused at once, naming the first (:class:`~brdf_infer.errors.BadInputError`,
  exit code 2 on the command line).
- The marker goes when the writer finishes: a folder that has it is incomplete (its writer died,
  or stopped on an error after changing the folder). Readers (:func:`require_complete`:
  ``report``, ``tis --run``, ``export --run``, …) refuse it in one line; the next writer takes
  it over and removes the temporary files of atomic writes the dead one left. A folder without
  a marker (made by hand, or by an older version) is complete.
- A writer stopped by an error before changing the folder (the listing of its names, inodes
  and modification times is the one it found) leaves it as it was: the folders it created go
  (bad input creates no folder), an earlier writer's marker stays.
- Adders (``report``, the export record of ``export --run``) require the folder complete and
  hold ``.brdf-infer.adding.lock``: one at a time; one that dies leaves the folder complete.
- Each shard of a batch (``batch --shard K/N``) holds ``.brdf-infer.shard-K-of-N.lock``: shards
  write one folder side by side, a plain writer and a shard refuse each other.

Claims are per process and re-entrant (``run`` holds its folder and calls ``posterior`` and
``report`` on it). POSIX only: without ``fcntl`` (Windows) or on a file system that refuses
``flock`` (some network mounts) the marker still tells complete from incomplete, but a second
writer is not refused, and a :class:`UserWarning` says so.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import re
import socket
import threading
import time
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from brdf_infer.errors import BadInputError

try:
    import fcntl
except ImportError:  # Windows
    fcntl = None

LOCK_FILE = ".brdf-infer.lock"
ADDING_LOCK_FILE = ".brdf-infer.adding.lock"
_MARKER = re.compile(r"^\.brdf-infer\..*lock$")  # every marker and lock file
_TEMPORARY = re.compile(r"^\..+\.[0-9a-f]{8}\.tmp$")  # brdf_infer._internal.atomic's
_NO_LOCKS = {errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL, errno.EBADF}
_ATTEMPTS, _RETRY_SECONDS = 10, 0.02  # a reader probing a marker holds it for microseconds


def shard_lock_file(index: int, count: int) -> str:
    """The marker of shard ``index`` of ``count`` of a batch (module docstring)."""
    return f".brdf-infer.shard-{index}-of-{count}.lock"


@dataclass
class Claim:
    """``folder`` held for writing (``previous``: the record of an unfinished write it took
    over)."""

    folder: Path
    previous: dict | None
    _path: Path
    _fd: int
    _before: set[tuple[str, int, int]] | None  # the folder's listing when taken (not adders)
    _created: list[Path]
    _count: int = 0


_HELD: dict[Path, Claim] = {}
_GUARD = threading.RLock()  # re-entrant: an adder checks the folder while holding it


def _key(folder: str | Path) -> Path:
    return Path(os.path.abspath(folder))


def _read(path: Path) -> dict | None:
    """The record in the marker ``path`` (None: none, or empty)."""
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
        return json.loads(text) if text.strip() else None
    except OSError:
        return None
    except ValueError:
        return {"command": "?"}


def _describe(record: dict | None) -> str:
    """``'brdf-infer run' (process 123 on host, started 2026-11-24 10:00:00)``."""
    if not record:
        return "another process"
    return (
        f"'brdf-infer {record.get('command', '?')}' (process {record.get('pid', '?')} on "
        f"{record.get('host', '?')}, started {record.get('started', '?')})"
    )


def _write(fd: int, record: dict) -> None:
    os.ftruncate(fd, 0)
    os.pwrite(fd, (json.dumps(record) + "\n").encode(), 0)
    os.fsync(fd)


def _lock(fd: int, folder: Path) -> bool:
    """Take the exclusive flock of ``fd`` without waiting: False when another process holds
    it; True, with a warning, where there are no locks (module docstring)."""
    try:
        if fcntl is None:
            raise OSError(errno.ENOSYS, "no fcntl on this platform")
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    except OSError as error:
        if error.errno not in _NO_LOCKS:
            raise
        warnings.warn(
            f"{folder}: no file locks here ({error.strerror}): a second writer is not refused",
            stacklevel=4,
        )
    return True


def _held_by_another(path: Path) -> bool:
    """Another live process holds the marker ``path``."""
    with contextlib.suppress(OSError, AttributeError), open(path, "rb") as stream:
        try:  # no locks here, or no fcntl: not held; closing the file drops the lock
            fcntl.flock(stream.fileno(), fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return True
    return False


def _open_locked(path: Path) -> int | None:
    """An open descriptor of the marker ``path``, locked; None when another process holds it."""
    for _ in range(_ATTEMPTS):
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            same = _lock(fd, path.parent) and os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False  # its writer finished and removed it just now
        if same:
            return fd
        os.close(fd)
        time.sleep(_RETRY_SECONDS)
    return None


def _listing(folder: Path) -> set[tuple[str, int, int]]:
    """Every entry under ``folder`` but the markers: (path, inode, modification time [ns])."""
    found = set()
    for root, folders, files in os.walk(folder):
        for name in folders + files:
            if not _MARKER.match(name):
                with contextlib.suppress(OSError):
                    status = os.lstat(os.path.join(root, name))
                    found.add((os.path.join(root, name), status.st_ino, status.st_mtime_ns))
    return found


def _remove_created(created: list[Path]) -> None:
    for path in reversed(created):
        with contextlib.suppress(OSError):
            path.rmdir()  # only if empty


def _conflict(folder: Path, mine: str) -> Path | None:
    """A live marker of another writer that ``mine`` excludes (a plain writer and a shard)."""
    for path in folder.iterdir():
        others = path.name not in (mine, ADDING_LOCK_FILE) and _MARKER.match(path.name)
        if others and LOCK_FILE in (mine, path.name) and _held_by_another(path):
            return path
    return None


def _acquire(folder: Path, command: str, option: str, adds: bool, marker: str) -> Claim:
    if adds:
        require_complete(folder)
    # the folders to create (not for an adder), outermost first
    created = [] if adds else [p for p in (folder, *folder.parents) if not p.exists()][::-1]
    path, fd = folder / (ADDING_LOCK_FILE if adds else marker), None
    try:
        for missing in created:
            missing.mkdir()
        fd = _open_locked(path)
        holder = path if fd is None else None if adds else _conflict(folder, marker)
        if holder is None:
            previous = None if adds else _read(path)
            started = time.strftime("%Y-%m-%d %H:%M:%S")
            host, pid = socket.gethostname(), os.getpid()
            _write(fd, {"pid": pid, "host": host, "command": command, "started": started})
    except OSError as error:
        holder = error
    if holder is not None:
        if fd is not None:
            if not _read(path):
                path.unlink(missing_ok=True)  # this call created it
            os.close(fd)
        _remove_created(created)
        problem = (
            f"cannot write here: {holder.strerror or holder}"
            if isinstance(holder, OSError)
            else f"is being written by {_describe(_read(holder))}: one writer per folder (wait "
            f"for it, or choose another {option})"
        )
        raise BadInputError(problem, file=folder, field=option)
    if previous is not None:
        for root, _, files in os.walk(folder):
            for name in filter(_TEMPORARY.match, files):
                with contextlib.suppress(OSError):
                    os.unlink(os.path.join(root, name))
    return Claim(folder, previous, path, fd, None if adds else _listing(folder), created)


def _release(claim: Claim, error: BaseException | None) -> None:
    """The marker goes when the write completed or changed nothing (a created folder too); it
    stays, marked as stopped, when an error interrupted a write that changed the folder."""
    try:
        if claim._before is None or error is None:
            claim._path.unlink(missing_ok=True)  # before the lock goes: no reader sees it free
            if claim._before is not None and claim._path.name == LOCK_FILE:  # dead shards'
                for path in claim.folder.iterdir():
                    if _MARKER.match(path.name) and not _held_by_another(path):
                        path.unlink(missing_ok=True)
        elif _listing(claim.folder) != claim._before:
            _write(claim._fd, {**(_read(claim._path) or {}), "stopped": type(error).__name__})
        elif claim.previous is not None:
            _write(claim._fd, claim.previous)  # took over an unfinished folder, changed nothing
        else:
            claim._path.unlink(missing_ok=True)
            _remove_created(claim._created)
    finally:
        os.close(claim._fd)


@contextlib.contextmanager
def writing(
    folder: str | Path,
    command: str,
    *,
    option: str = "out",
    adds: bool = False,
    marker: str = LOCK_FILE,
) -> Iterator[Claim]:
    """Hold ``folder`` (created with its parents if missing) for writing (module docstring).

    Args:
        command: the writer, as a refusal names it (``run``, ``batch --shard 1/4``, …).
        option: the option that named the folder, for messages.
        adds: only adds to a complete folder (``report``; one that dies leaves it complete).
        marker: the writer's marker file (a batch shard's: :func:`shard_lock_file`).

    Raises:
        BadInputError: another process writes (or, ``adds``, adds to) ``folder``, it cannot
            be created or written, or (``adds``) it is incomplete.
    """
    key = _key(folder)
    with _GUARD:
        claim = _HELD.get(key)
        if claim is None:
            claim = _HELD[key] = _acquire(Path(folder), command, option, adds, marker)
        claim._count += 1
    try:
        yield claim
    except BaseException as error:
        _leave(key, claim, error)
        raise
    _leave(key, claim, None)


def _leave(key: Path, claim: Claim, error: BaseException | None) -> None:
    with _GUARD:
        claim._count -= 1
        if claim._count:
            return
        del _HELD[key]
    _release(claim, error)


def require_complete(folder: str | Path) -> None:
    """Refuse a results folder that is being written or that a writer left incomplete.

    Raises:
        BadInputError: one line naming the folder and its writer.
    """
    folder = Path(folder)
    with _GUARD:
        if _key(folder) in _HELD or not folder.is_dir():
            return
    for path in sorted(folder.iterdir()):
        if path.name == ADDING_LOCK_FILE or not _MARKER.match(path.name):
            continue
        record = _read(path)
        if _held_by_another(path):
            raise BadInputError(
                f"is being written by {_describe(record)}; wait until it finishes", file=folder
            )
        why = f" ({record['stopped']})" if record and record.get("stopped") else ""
        raise BadInputError(
            f"incomplete: {_describe(record).replace('another process', 'a writer')} stopped "
            f"before finishing it{why}; run that command again",
            file=folder,
        )
