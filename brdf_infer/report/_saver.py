"""The report's figures saved as PNG by a second process while this one makes the next ones
and writes the tables: drawing and encoding are most of a figure's cost, and a figure pickles
in hundredths of a second.

The second process is a bare interpreter that imports matplotlib only (``python -c``; a
multiprocessing worker would import this package, its JAX and ArviZ: seconds of start-up),
started before the run is read where there is a second core (:func:`spare_core`). The figures
travel as pickles through a temporary folder, one line on its standard input each, and it
answers each with the line once the PNG is written. Whatever it cannot take (it did not start,
it failed, a figure that does not pickle) this process saves itself, to the same bytes.
"""

from __future__ import annotations

import contextlib
import os
import pickle
import select
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import matplotlib.pyplot as plt
from matplotlib.figure import Figure

from brdf_infer.report._raytrace import figure_png, png_options

BACKLOG = 1  # figures it may have waiting; beyond, this process saves the next one itself

_SAVER = """\
import pickle, sys
from pathlib import Path
import matplotlib.figure, matplotlib.backends.backend_agg
folder = Path(sys.argv[1])
for line in sys.stdin:
    name = line.strip()
    figure, options = pickle.loads((folder / f"{name}.pickle").read_bytes())
    figure.savefig(folder / f"{name}.png", **options)
    print(name, flush=True)
"""


def spare_core() -> bool:
    """Whether this process may run on more than one core. Not the load average: after
    sampling on every core, the 1-minute average counts this run's own chains for a minute
    and kept the second process out of every ``brdf-infer run``; on a machine busy with other
    work the second process adds its start-up and the pickles (≈ 0.3 s of CPU) to the load."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return (cores or 1) > 1


class FigureSaver:
    """PNG bytes of figures by name: :meth:`save` each, :meth:`png` waits for one. The second
    process saves a figure when it has at most :data:`BACKLOG` waiting, this one otherwise,
    and every figure it took and did not save if it fails (``progress`` says so). A context
    manager: the second process and the folder end with it."""

    def __init__(self, progress: Callable[[str], object] = print, second: bool | None = None):
        """``second``: whether to start the second process (default: where a core is free
        for it, :func:`spare_core`)."""
        self._progress = progress
        self._temporary = tempfile.TemporaryDirectory(prefix="brdf_infer_figures_")
        self._folder = Path(self._temporary.name)
        self._log = (self._folder / "saver.log").open("w+b")
        self._here: dict[str, bytes] = {}  # saved by this process
        self._waiting: list[str] = []  # handed over, not yet answered
        self._answers = b""
        self._process: subprocess.Popen | None = None
        if not (spare_core() if second is None else second):
            return
        try:
            self._process = subprocess.Popen(
                [sys.executable, "-c", _SAVER, str(self._folder)],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=self._log,
                env={**os.environ, "MPLBACKEND": "agg"},
            )
            os.set_blocking(self._process.stdout.fileno(), False)
        except OSError as error:  # no interpreter to start (an embedded Python)
            progress(f"  figures saved here: no second process ({error})")

    def save(self, name: str, figure: Figure) -> None:
        """``figure`` saved as ``name`` (every name once), here or by the second process."""
        if not self._handed_over(name, figure):
            self._here[name] = figure_png(figure)

    def png(self, name: str) -> bytes:
        """The PNG of the figure saved as ``name``, once it is written."""
        while name in self._waiting and self._running():
            select.select([self._process.stdout], [], [])
            self._answered()
        self._answered()
        if name in self._waiting:  # the second process ended without saving it
            self._take_back()
        if name in self._here:
            return self._here[name]
        return (self._folder / f"{name}.png").read_bytes()

    def _running(self) -> bool:
        return self._process is not None and self._process.poll() is None

    def _handed_over(self, name: str, figure: Figure) -> bool:
        """Whether the second process took ``figure``: running, at most :data:`BACKLOG`
        figures waiting, and the figure pickles."""
        self._answered()
        if not self._running() or len(self._waiting) > BACKLOG:
            return False
        try:
            payload = pickle.dumps((figure, png_options()))
        except (pickle.PicklingError, TypeError, AttributeError):  # an artist that won't pickle
            return False
        (self._folder / f"{name}.pickle").write_bytes(payload)
        try:
            self._process.stdin.write(f"{name}\n".encode())
            self._process.stdin.flush()
        except BrokenPipeError:  # it has ended since
            return False
        plt.close(figure)  # as figure_png would (a figure pyplot made)
        self._waiting.append(name)
        return True

    def _answered(self) -> None:
        """Take the names the second process has answered off :attr:`_waiting`."""
        if self._process is None:
            return
        with contextlib.suppress(BlockingIOError):  # nothing new
            self._answers += self._process.stdout.read() or b""
        *done, self._answers = self._answers.split(b"\n")
        for name in done:
            self._waiting.remove(name.decode())

    def _take_back(self) -> None:
        """Save here every figure the second process took and did not save: it failed."""
        self._log.seek(0)
        error = self._log.read().decode(errors="replace").strip().splitlines()
        self._progress(
            f"  the second process saving figures failed (exit code {self._process.returncode}"
            f"{': ' + error[-1] if error else ''}): {', '.join(self._waiting)} saved here"
        )
        for name in self._waiting:
            figure, _ = pickle.loads((self._folder / f"{name}.pickle").read_bytes())
            self._here[name] = figure_png(figure)
        self._waiting.clear()

    def __enter__(self) -> FigureSaver:
        return self

    def __exit__(self, *error) -> None:
        if self._process is not None:
            if self._process.poll() is None:
                self._process.kill()
                self._process.wait()
            for stream in (self._process.stdin, self._process.stdout):
                with contextlib.suppress(OSError):  # a pipe to a process that has ended
                    stream.close()
        self._log.close()
        self._temporary.cleanup()
