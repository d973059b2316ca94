"""A batch's entries and result: one per scene, with its run or its error, and the
exception that a cancelled batch raises."""

from __future__ import annotations

import signal
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from brdf_infer.runs.folder import BATCH_FILE
from brdf_infer.runs.records import Bands, PosteriorSummary
from brdf_infer.scene import Scene

INTERRUPTED = "interrupted before its run was complete"


@dataclass
class SceneEntry:
    """One scene of a batch: where it came from, and its run or its error.

    Attributes:
        done: its run folder is complete and in place.
    """

    source: str
    scene: Scene | None = None
    out: Path | None = None
    summary: PosteriorSummary | None = None
    tis: dict[str, list] | None = None
    error: str | None = None
    done: bool = False
    forced: list[str] = field(default_factory=list)

    def as_json(self) -> dict[str, Any]:
        diagnostics = (self.summary or {}).get("diagnostics", {})
        ess = [diagnostics.get("ess_bulk_min"), diagnostics.get("ess_tail_min")]
        unfinished = self.error is None and not self.done
        return {
            "scene": self.scene.name if self.scene is not None else self.source,
            "source": self.source,
            "out": None if self.out is None or unfinished else str(self.out),
            "model": None if self.summary is None else self.summary["model"],
            "r_hat_max": diagnostics.get("r_hat_max"),
            "ess_min": None if None in ess else min(ess),
            "divergences": diagnostics.get("divergences"),
            "verdict": None if self.summary is None else self.summary["verdict"],
            "tis": self.tis,
            "error": INTERRUPTED if unfinished else self.error,
        }


@dataclass
class BatchResult:
    """Every scene's entry, the number of compiled groups and devices, and the wall time
    (``interrupted``: the batch was cancelled; entries not ``done`` have no run folder).

    Attributes:
        shards: the shards the batch was run in (``brdf-infer batch --shard K/N``: ``N``).
        compile_seconds: [s] compiling, in this process.
        merged: the result of the whole batch (False: a shard's own scenes only, written
            before the other shards finished; no ``batch.json``).
    """

    entries: list[SceneEntry]
    groups: int
    devices: int
    seconds: float
    compile_seconds: float
    interrupted: bool = False
    shards: int = 1
    merged: bool = True

    @property
    def complete(self) -> int:
        """Scenes whose run folder is complete."""
        return sum(entry.done for entry in self.entries)

    def as_json(self) -> dict[str, Any]:
        return {
            "scenes": [entry.as_json() for entry in self.entries],
            "groups": self.groups,
            "devices": self.devices,
            "shards": self.shards,
            "seconds": self.seconds,
            "compile_seconds": self.compile_seconds,
            "interrupted": self.interrupted,
        }


class BatchInterrupted(Exception):
    """A batch stopped by its ``cancel`` event (or a signal): ``result`` holds every entry,
    the complete ones ``done``; ``signum`` the signal, if one stopped it."""

    def __init__(self, result: BatchResult, signum: int | None = None):
        super().__init__(f"batch interrupted: {result.complete} scene(s) complete")
        self.result = result
        self.signum = signum

    @property
    def exit_code(self) -> int:
        """128 + the signal number (130 for SIGINT, 143 for SIGTERM); 130 without a signal."""
        return 128 + (self.signum if self.signum is not None else signal.SIGINT)

    def message(self, out: Path) -> str:
        """One line: what stopped the batch and how many scene folders are complete."""
        name = signal.Signals(self.signum).name if self.signum is not None else "cancelled"
        total = sum(entry.error is None for entry in self.result.entries)
        listed = f" (listed in {BATCH_FILE})" if self.result.shards == 1 else ""
        return (
            f"interrupted ({name}): {self.result.complete} of {total} scene(s) complete in "
            f"{out}{listed}; no partial folder left (continue with --resume)"
        )


def _tis_entry(bands: Bands) -> dict[str, list] | None:
    """The TIS band of a run's bands, as a batch entry lists it."""
    band = bands.get("tis")
    return None if band is None else {k: band[k] for k in ("theta_i_deg", "median", "lo95", "hi95")}
