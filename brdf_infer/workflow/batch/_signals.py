"""A batch that SIGINT or SIGTERM stops: :func:`run_batch_until_signalled`."""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from brdf_infer._internal.shards import WHOLE, Shard
from brdf_infer.scene.settings import BatchSettings
from brdf_infer.workflow.batch._batch import Batch, _silent
from brdf_infer.workflow.batch._entries import BatchInterrupted, BatchResult

GRACE_SECONDS = 3.0  # after a signal, how long the batch may take to stop on its own


def run_batch_until_signalled(
    sources: list[str],
    out: Path,
    settings: BatchSettings = BatchSettings(),
    *,
    model: str | None = None,
    progress: Callable[[str], None] = _silent,
    signals: tuple[int, ...] = (signal.SIGINT, signal.SIGTERM),
    grace: float = GRACE_SECONDS,
    resume: bool = False,
    shard: Shard = WHOLE,
) -> BatchResult:
    """:func:`run_batch` that SIGINT or SIGTERM stops (call from the main thread).

    The batch runs in a worker thread while this thread waits for it, so a signal is seen at
    once even while a program compiles. The signal sets the batch's cancel event; the batch
    then stops at its next check (between sampling chunks where ``run_many`` takes the
    event, between run folders), removes the folder it was writing and writes ``batch.json``.
    If it has not stopped after ``grace`` seconds (or at a second signal) this thread removes
    the folders being written and writes ``batch.json`` itself, and the exception says so
    (``hard``: the process must end with ``os._exit``: the worker threads cannot be joined).

    Raises:
        BatchInterrupted: a signal stopped the batch (``signum``, ``exit_code``, and ``hard``).
    """
    batch = Batch(
        sources, out, settings, model=model, progress=progress, resume=resume, shard=shard
    )
    if threading.current_thread() is not threading.main_thread():  # no signals here
        return batch.run()
    outcome: dict[str, Any] = {}
    received: list[tuple[int, float]] = []  # (the signal, when)

    def on_signal(signum, frame) -> None:
        del frame
        received.append((signum, time.monotonic()))
        batch.cancel.set()

    def work() -> None:
        try:
            outcome["result"] = batch.run()
        except BaseException as error:  # handed to the waiting thread
            outcome["error"] = error

    previous = {number: signal.signal(number, on_signal) for number in signals}
    try:
        worker = threading.Thread(target=work, name="brdf-infer-batch", daemon=True)
        worker.start()
        while worker.is_alive():
            worker.join(0.05)
            if received:
                deadline = received[0][1] + grace if len(received) == 1 else received[1][1]
                if time.monotonic() >= deadline:
                    break
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
    signum = received[0][0] if received else None
    if worker.is_alive():  # did not stop in time: stop it from here
        interrupted = BatchInterrupted(batch.write_summary(interrupted=True), signum)
        batch.abandon()  # last, so that the process ends right after (a writer may still run)
        raise interrupted
    error = outcome.get("error")
    if isinstance(error, BatchInterrupted) or (error is None and received):
        result = error.result if error is not None else outcome["result"]
        raise BatchInterrupted(result, signum)
    if error is not None:
        raise error
    return outcome["result"]
