"""Run folders of a batch: their names, and the half-written ones a killed batch left."""

from __future__ import annotations

import glob
import shutil
from pathlib import Path

from brdf_infer.workflow.batch._entries import SceneEntry

PARTIAL_MARK = ".partial-"  # out/.<scene>.partial-<pid>: a run folder being written
OLD_MARK = ".old-"  # out/.<scene>.old-<pid>: the folder a complete one is replacing


def _folder_names(entries: list[SceneEntry]) -> list[str]:
    """One folder name per scene: its name, made unique with a suffix where names repeat."""
    names, seen = [], {}
    for entry in entries:
        base = entry.scene.name if entry.scene is not None else Path(entry.source).stem
        seen[base] = seen.get(base, 0) + 1
        names.append(base if seen[base] == 1 else f"{base}-{seen[base]}")
    return names


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def remove_stale_partials(out: Path, names: list[str]) -> list[Path]:
    """Remove the half-written run folders of the scene folders ``names`` in ``out`` that a
    batch killed outright (SIGKILL, power loss) left: ``.<scene>.partial-<pid>`` (and
    ``.<scene>.old-<pid>``, the folder it was replacing). Call while holding ``out`` for
    those scenes (no other process writes them)."""
    removed = []
    for name in names:
        for mark in (PARTIAL_MARK, OLD_MARK):
            for path in out.glob(f".{glob.escape(name)}{mark}*"):
                _remove(path)
                removed.append(path)
    return removed
