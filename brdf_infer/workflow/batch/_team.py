"""The processes of one batch working together: ``jax.distributed`` to start them, files in the
output folder to hear from each other.

``jax.distributed.initialize`` starts the coordinator in process 0 and waits until every
process has connected; one broadcast (``multihost_utils.broadcast_one_to_all``) then gives all
of them the run's token, and with it the folder ``OUT/.batch-<token>/`` through which they
talk (the output folder is shared by every process anyway, since each writes its scenes'
run folders there; public JAX has no key-value store to do it):

- ``alive-<i>``: process ``i``'s heartbeat, a counter rewritten every second;
- ``failed-<i>``: why process ``i`` stopped (written by itself, or by process 0 when ``i``'s
  heartbeat stopped for ``peer_timeout`` seconds: killed, or its host gone);
- ``part-<i>.json``: the ``batch.json`` entries of the scenes process ``i`` ran;
- ``written``: process 0 wrote ``batch.json``; ``left-<i>``: process ``i`` disconnected.

Process 0 leaves last: JAX ends every process still connected when the coordinator goes
(``jax_enable_recoverability`` keeps the others running when any other process dies).
"""

from __future__ import annotations

import contextlib
import json
import os
import secrets
import shutil
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import jax
import numpy as np

from brdf_infer._internal.processes import Processes
from brdf_infer.errors import BadInputError

LEAVE_SECONDS = 10.0  # [s] how long process 0 waits for the others to disconnect


def join_processes(processes: Processes) -> None:
    """Connect this process to the others (``jax.distributed.initialize``; call before JAX
    computes anything): returns once every process has connected.

    Raises:
        BadInputError: the coordinator cannot be reached, or not every process came in time.
    """
    jax.config.update("jax_enable_recoverability", True)
    try:
        jax.distributed.initialize(
            processes.coordinator,
            processes.count,
            processes.index,
            initialization_timeout=max(60, int(5 * processes.peer_timeout)),
            # JAX's own verdict comes long after ours (``peer_timeout``)
            heartbeat_timeout_seconds=int(2 * processes.peer_timeout + 60),
            shutdown_timeout_seconds=int(LEAVE_SECONDS),
        )
    except (RuntimeError, ValueError) as error:  # jax's errors: a timeout, a bad address
        first = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
        raise BadInputError(
            f"cannot start process {processes.index} of {processes.count}: {first}",
            field="coordinator",
        ) from None


class Team:
    """This process's view of the others (module docstring); ``failure`` says which one
    failed, and ``cancel`` (when given) is set at once."""

    def __init__(self, processes: Processes, folder: Path, cancel: threading.Event | None = None):
        self.processes, self.folder = processes, folder
        self.cancel = cancel
        self.failure: str | None = None
        self.interval = min(1.0, processes.peer_timeout / 5)
        self._stop = threading.Event()
        self._seen: dict[int, tuple[str | None, float]] = {}
        self._watcher = threading.Thread(target=self._watch, name="brdf-infer-team", daemon=True)

    # ------------------------------------------------------------------------------ start

    @classmethod
    def start(cls, processes: Processes, out: Path, problem: str | None = None) -> Team | None:
        """Agree on the run's folder with the others (process 0 creates it) and start the
        heartbeat. ``problem``: process 0 cannot run the batch (its one-line error); the
        others learn it here.

        Returns:
            The team; None (process 0, a ``problem``) once the others have left.

        Raises:
            PeerFailed: (processes other than 0) process 0 could not start the batch.
        """
        ours = secrets.randbits(62) | 1 if processes.index == 0 and problem is None else 0
        if ours:  # process 0 holds ``out``: a run's folder there is a killed batch's
            for stale in out.glob(".batch-*"):
                shutil.rmtree(stale, ignore_errors=True)
        from jax.experimental import multihost_utils

        with _stdout_to_stderr():  # gloo greets on stdout when it connects
            token = int(multihost_utils.broadcast_one_to_all(np.array(ours, dtype=np.int64)))
        if token == 0:  # process 0 cannot run it: the others leave first (JAX: module docstring)
            if processes.index != 0:
                _disconnect()
                raise PeerFailed(f"process 0 of {processes.count} could not start the batch")
            time.sleep(2.0)
            _disconnect()
            return None
        team = cls(processes, out / f".batch-{token:016x}")
        team.folder.mkdir(parents=True, exist_ok=True)
        team._watcher.start()
        return team

    # ------------------------------------------------------------------------------ heartbeat

    def _path(self, name: str, index: int | None = None) -> Path:
        return self.folder / (name if index is None else f"{name}-{index}")

    def _others(self) -> list[int]:
        return [i for i in range(self.processes.count) if i != self.processes.index]

    def _watch(self) -> None:
        beat = 0
        while not self._stop.wait(self.interval):
            beat += 1
            try:
                _put(self._path("alive", self.processes.index), str(beat).encode())
                self._look()
            except OSError as error:  # the shared folder is gone: we cannot go on either
                self._fail_with(f"the run's folder {self.folder} cannot be used: {error}")

    def _look(self) -> None:
        for index in range(self.processes.count):
            reason = _read(self._path("failed", index))
            if reason is not None and index != self.processes.index:
                self._fail_with(f"process {index} of {self.processes.count} failed: {reason}")
        if self.processes.index != 0:
            return
        now = time.monotonic()
        for index in self._others():
            if self._path("left", index).exists() or self._path("failed", index).exists():
                continue
            beat = _read(self._path("alive", index))
            last, since = self._seen.get(index, (None, now))
            self._seen[index] = (beat, now if beat != last else since)
            if now - self._seen[index][1] > self.processes.peer_timeout:
                seconds = self.processes.peer_timeout
                reason = f"stopped responding (no heartbeat for {seconds:g} s: killed?)"
                _put(self._path("failed", index), reason.encode())
                self._fail_with(f"process {index} of {self.processes.count} {reason}")

    def _fail_with(self, message: str) -> None:
        if self.failure is None:
            self.failure = message
        if self.cancel is not None:
            self.cancel.set()

    # ------------------------------------------------------------------------------ parts

    def post_part(self, part: dict[str, Any]) -> None:
        """This process's ``batch.json`` entries: ``{"scenes": {index: entry}, ...}``."""
        data = json.dumps(part).encode()
        _put(self._path(f"part-{self.processes.index}.json"), data)

    def parts(self) -> list[dict[str, Any]]:
        """The parts posted so far by the other processes."""
        found = []
        for index in self._others():
            text = _read(self._path(f"part-{index}.json"))
            if text is not None:
                found.append(json.loads(text))
        return found

    def wait_for(self, done: Callable[[], bool], stop: Callable[[], None]) -> None:
        """Wait until ``done()``; ``stop()`` is called (it raises) once the batch is to stop."""
        while not done():
            if self.failure is not None or (self.cancel is not None and self.cancel.is_set()):
                stop()
            time.sleep(self.interval / 4)

    def all_parts_posted(self) -> bool:
        others = self._others()
        return all(self._path(f"part-{i}.json").exists() for i in others)

    def mark_written(self) -> None:
        """Process 0 wrote ``batch.json``."""
        _put(self._path("written"), b"")

    def written(self) -> bool:
        return self._path("written").exists()

    # ------------------------------------------------------------------------------ end

    def fail(self, reason: str) -> None:
        """Tell the others that this process stops, and why (one line)."""
        if self.folder.is_dir():
            _put(self._path("failed", self.processes.index), reason.encode())

    def leave(self) -> None:
        """Disconnect (process 0: after every other process that is not known to have died,
        waiting at most ``LEAVE_SECONDS``; then the run's folder goes)."""
        self._stop.set()
        if self.processes.index != 0:
            _disconnect()
            if self.folder.is_dir():
                _put(self._path("left", self.processes.index), b"")
            return
        deadline = time.monotonic() + LEAVE_SECONDS
        while time.monotonic() < deadline and not all(
            self._path("left", i).exists() or self._path("failed", i).exists()
            for i in self._others()
        ):
            time.sleep(0.05)
        time.sleep(0.2)  # their connections close as their processes end
        shutil.rmtree(self.folder, ignore_errors=True)
        _disconnect()


class PeerFailed(Exception):
    """Another process of the batch failed (the message names it); this one stopped."""


def _put(path: Path, data: bytes) -> None:
    """Write ``path`` whole (a reader sees the old file or the new one); not noted as a write
    of the output folder's claim: the run's folder goes when the batch ends."""
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    temporary.write_bytes(data)
    os.replace(temporary, path)


def _read(path: Path) -> str | None:
    try:
        return path.read_text()
    except OSError:
        return None


@contextlib.contextmanager
def _stdout_to_stderr() -> Iterator[None]:
    """File descriptor 1 points to stderr meanwhile (what C++ libraries print included), so
    that stdout keeps only the command's output (``--json``)."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        os.dup2(2, 1)
        yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


def _disconnect() -> None:
    try:
        jax.distributed.shutdown()
    except Exception as error:
        print(f"brdf-infer: note: leaving jax.distributed: {error}", file=sys.stderr)
