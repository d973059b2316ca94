"""One writer per results folder, and a folder that says whether it is complete.

A command writing a results folder holds the file ``.brdf-infer.lock`` in it from before its
first write until its last: the file names the writer (process id, host, command, start) and
carries an advisory lock (:mod:`brdf_infer._internal.oslock`: ``flock``, Windows'
``msvcrt.locking``, or the record itself where neither exists) for as long as the writer lives.

- A second writer of the same folder is refused at once, while the first one runs
  (:class:`~brdf_infer.errors.BadInputError`, exit code 2 on the command line).
- The file is removed when the writer finishes. A writer that dies (``kill -9``, power loss) or
  stops on an error after it wrote something leaves it behind: the folder is incomplete, and
  every reader (:func:`require_complete`: ``report``, ``tis --run``, ``export --run``, …)
  refuses it in one line. The next command that produces the folder takes the stale file over
  (the kernel released the dead writer's lock), removes the temporary files the dead writer
  left, and writes the folder again.
- A command that only adds to a complete folder (``report``, the export record of
  ``export --run``) requires it complete and holds ``.brdf-infer.adding.lock`` instead: one
  adder at a time, and an adder that dies leaves the folder complete (its files are written
  atomically; the next adder takes its lock over).
- A writer that stops before writing anything leaves nothing: the lock file goes, and so do
  the folders it created for it (bad input creates no folder).

Claims are per process and re-entrant: ``run`` holds its folder and calls ``posterior`` and
``report`` on it. The lock guards processes on one machine (a file system without locks, some
network mounts, is written without the lock).
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import socket
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from brdf_infer._internal import oslock
from brdf_infer.errors import BadInputError

LOCK_FILE = ".brdf-infer.lock"
ADDING_LOCK_FILE = ".brdf-infer.adding.lock"
# the temporary files of brdf_infer._internal.atomic (8 random characters)
_TEMPORARY = re.compile(r"^\..+\.[A-Za-z0-9_]{8}\.tmp$")
_ATTEMPTS = 10  # a reader probing the lock holds it for microseconds: retry before refusing
_RETRY_SECONDS = 0.02
_CLOEXEC = getattr(os, "O_CLOEXEC", 0)  # Python's descriptors are not inherited anyway


@dataclass(frozen=True)
class Owner:
    """The writer a lock file names (``stopped``: why it stopped before finishing, if it
    said so)."""

    pid: int | None
    host: str
    command: str
    started: str
    stopped: str | None = None

    def describe(self) -> str:
        """``'brdf-infer run' (process 123 on host, started 2026-11-24 10:00:00)``."""
        process = "an unknown process" if self.pid is None else f"process {self.pid}"
        return f"'brdf-infer {self.command}' ({process} on {self.host}, started {self.started})"

    def as_json(self) -> dict:
        return {
            "pid": self.pid,
            "host": self.host,
            "command": self.command,
            "started": self.started,
            "stopped": self.stopped,
        }


@dataclass
class Claim:
    """A folder held for writing.

    Attributes:
        folder: the folder.
        previous: the writer of an unfinished earlier write this claim took over, if any.
    """

    folder: Path
    previous: Owner | None = None
    _adds: bool = False
    _fd: int | None = None
    _owner: Owner | None = None
    _count: int = 0
    _written: bool = False
    _created: list[Path] = field(default_factory=list)


_HELD: dict[Path, Claim] = {}
_GUARD = threading.RLock()  # re-entrant: an adder checks the folder while holding it


def _key(folder: Path) -> Path:
    return Path(os.path.abspath(folder))


def holds(folder: str | Path) -> bool:
    """This process holds ``folder`` for writing."""
    with _GUARD:
        return _key(Path(folder)) in _HELD


def note_written(path: str | Path) -> None:
    """Record that ``path`` was written (called by every atomic write and folder rename), so
    that a claim stopped by an error knows whether its folder changed."""
    path = _key(Path(path))
    with _GUARD:
        for folder, claim in _HELD.items():
            if path == folder or folder in path.parents:
                claim._written = True


def _read_owner(path: Path) -> Owner | None:
    """The writer named in the lock file ``path`` (None: no file, or empty)."""
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return None
    if not text.strip():
        return None
    try:
        record = json.loads(text)
        return Owner(
            pid=int(record["pid"]) if record.get("pid") is not None else None,
            host=str(record.get("host", "?")),
            command=str(record.get("command", "?")),
            started=str(record.get("started", "?")),
            stopped=record.get("stopped"),
        )
    except (ValueError, TypeError, KeyError, AttributeError):
        return Owner(None, "?", "?", "?")


def _write_owner(fd: int, owner: Owner) -> None:
    data = (json.dumps(owner.as_json()) + "\n").encode()
    os.ftruncate(fd, 0)
    os.lseek(fd, 0, os.SEEK_SET)
    os.write(fd, data)
    os.fsync(fd)


def _same_file(fd: int, path: Path) -> bool:
    """``fd`` is still the file at ``path`` (a finishing writer unlinks the lock file)."""
    try:
        return os.stat(path).st_ino == os.fstat(fd).st_ino
    except FileNotFoundError:
        return False


def _is_locked(path: Path) -> bool:
    """Another process holds the lock file ``path`` (its writer is alive)."""
    try:
        fd = os.open(path, os.O_RDONLY | _CLOEXEC)
    except OSError:
        return False
    try:
        if oslock.try_lock(fd, exclusive=False):
            oslock.unlock(fd)
            return False
        return True
    except OSError:
        return False
    finally:
        os.close(fd)


def _make_folder(folder: Path, option: str) -> list[Path]:
    """Create ``folder`` and its missing parents; the folders created, outermost first."""
    missing = [p for p in (folder, *folder.parents) if not p.exists()][::-1]
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise BadInputError(
            f"cannot create the folder: {error.strerror or error}", file=folder, field=option
        ) from None
    return missing


def _remove_created(created: list[Path]) -> None:
    for path in reversed(created):
        with contextlib.suppress(OSError):
            path.rmdir()  # only if empty


def _remove_debris(folder: Path) -> None:
    """Remove the temporary files of atomic writes a dead writer left in ``folder``."""
    for root, _, names in os.walk(folder):
        for name in names:
            if _TEMPORARY.match(name):
                with contextlib.suppress(OSError):
                    os.unlink(os.path.join(root, name))


def _now() -> str:
    return time.strftime("%Y-%m-%d %H:%M:%S")


def _open_locked(path: Path) -> tuple[int, bool] | None:
    """(an open, exclusively locked descriptor of the lock file ``path``, whether this call
    created the file); None when another process holds it."""
    for _ in range(_ATTEMPTS):
        try:
            fd, new = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL | _CLOEXEC, 0o644), True
        except FileExistsError:
            try:
                fd, new = os.open(path, os.O_RDWR | _CLOEXEC), False
            except FileNotFoundError:
                continue  # its writer finished and removed it just now: again
        if not oslock.try_lock(fd, exclusive=True, created=new):
            os.close(fd)
            time.sleep(_RETRY_SECONDS)
            continue
        if _same_file(fd, path):
            return fd, new
        os.close(fd)  # the file was removed (its writer finished) while we waited: again
    return None


def _acquire(folder: Path, command: str, option: str, adds: bool) -> Claim:
    if adds:
        require_complete(folder)
    created = [] if adds else _make_folder(folder, option)
    path = folder / (ADDING_LOCK_FILE if adds else LOCK_FILE)
    try:
        opened = _open_locked(path)
    except OSError as error:
        _remove_created(created)
        raise BadInputError(
            f"cannot write here: {error.strerror or error}", file=folder, field=option
        ) from None
    if opened is None:
        owner = _read_owner(path)
        _remove_created(created)
        who = owner.describe() if owner else "another process"
        raise BadInputError(
            f"is being written by {who}: one writer per folder (wait for it, or choose another "
            f"{option})",
            file=folder,
            field=option,
        )
    fd, new = opened
    previous = None if new else _read_owner(path) or Owner(None, "?", "?", "?")
    owner = Owner(os.getpid(), socket.gethostname(), command, _now())
    try:
        _write_owner(fd, owner)
    except OSError as error:
        os.close(fd)
        if new:
            with contextlib.suppress(OSError):
                path.unlink()
        _remove_created(created)
        raise BadInputError(
            f"cannot write here: {error.strerror or error}", file=folder, field=option
        ) from None
    if previous is not None:
        _remove_debris(folder)
    return Claim(folder, previous, adds, fd, owner, 0, False, created)


def _release(claim: Claim, error: BaseException | None) -> None:
    """Finish a claim: the lock file goes when the write completed or wrote nothing (or only
    added to the folder); it stays, marked as stopped, when an error interrupted a write."""
    path = claim.folder / (ADDING_LOCK_FILE if claim._adds else LOCK_FILE)
    fd, claim._fd = claim._fd, None
    if fd is None:
        return
    try:
        if claim._adds:
            with contextlib.suppress(FileNotFoundError):
                path.unlink()
        elif error is not None and not claim._written and claim.previous is not None:
            _write_owner(fd, claim.previous)  # took over an unfinished folder, wrote nothing
        elif error is None or not claim._written:
            with contextlib.suppress(FileNotFoundError):
                path.unlink()  # before the lock is released: no reader sees it unlocked
            if error is not None:
                _remove_created(claim._created)
        else:
            reason = type(error).__name__
            with contextlib.suppress(OSError):
                _write_owner(fd, Owner(**{**claim._owner.as_json(), "stopped": reason}))
    finally:
        os.close(fd)


@contextlib.contextmanager
def writing(
    folder: str | Path, command: str, *, option: str = "out", adds: bool = False
) -> Iterator[Claim]:
    """Hold ``folder`` (created with its parents if missing) for writing (module docstring).

    Args:
        folder: the results folder.
        command: the writer, as the refusal names it (``run``, ``batch``, …).
        option: the option that named the folder, for messages.
        adds: the command only adds to a complete folder (``report``): the folder must be
            complete, and an adder that dies leaves it complete.

    Raises:
        BadInputError: another process writes ``folder`` (or, ``adds``, adds to it); the
            folder cannot be created or written; or (``adds``) it is incomplete.
    """
    key = _key(Path(folder))
    with _GUARD:
        claim = _HELD.get(key)
        if claim is None:
            claim = _acquire(Path(folder), command, option, adds)
            _HELD[key] = claim
        claim._count += 1
    failure: BaseException | None = None
    try:
        yield claim
    except BaseException as error:
        failure = error
        raise
    finally:
        with _GUARD:
            claim._count -= 1
            last = claim._count == 0
            if last:
                del _HELD[key]
        if last:
            _release(claim, failure)


def _incomplete(owner: Owner | None) -> str:
    who = owner.describe() if owner else "a writer"
    why = f" ({owner.stopped})" if owner and owner.stopped else ""
    return f"incomplete: {who} stopped before finishing it{why}; run that command again"


def require_complete(folder: str | Path) -> None:
    """Refuse a results folder that is being written or that a writer left incomplete.

    Raises:
        BadInputError: one line naming the folder and its writer.
    """
    folder = Path(folder)
    path = folder / LOCK_FILE
    if holds(folder) or not path.exists():
        return
    owner = _read_owner(path)
    if _is_locked(path):
        who = owner.describe() if owner else "another process"
        raise BadInputError(f"is being written by {who}; wait until it finishes", file=folder)
    raise BadInputError(_incomplete(owner), file=folder)
