"""One batch run: load and group the scenes, run each group's program, write the run
folders."""

from __future__ import annotations

import contextlib
import dataclasses
import os
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import numpy as np

from brdf_infer._internal.outlock import require_complete, shard_lock_file, writing
from brdf_infer._internal.precision import ensure_float64
from brdf_infer._internal.shards import WHOLE, Shard
from brdf_infer.errors import BadInputError
from brdf_infer.posterior import (
    Cancelled,
    NutsProgram,
    build_model,
    chain_keys,
    complete_run,
    model_name,
    nuts_draws,
    pad_datasets,
    paddable,
    row_count,
    run_fingerprint,
    stack_data,
)
from brdf_infer.runs.folder import (
    BANDS_FILE,
    BATCH_FILE,
    POSTERIOR_FILE,
    SUMMARY_FILE,
    RunFolder,
)
from brdf_infer.scene import load_scene
from brdf_infer.scene.settings import BatchSettings
from brdf_infer.verdict.plausibility import measurement_checks, require_plausible
from brdf_infer.workflow.batch._entries import (
    BatchInterrupted,
    BatchResult,
    SceneEntry,
    _tis_entry,
)
from brdf_infer.workflow.batch._folders import (
    OLD_MARK,
    PARTIAL_MARK,
    _folder_names,
    _remove,
    remove_stale_partials,
)
from brdf_infer.workflow.batch._groups import _site_shapes, expand_sources, structure_key


def _silent(message: str) -> None:
    del message


class Batch:
    """One batch run (:func:`run_batch`), its state readable from another thread: the entries,
    the groups and the run folders being written.

    A ``shard`` of several runs and writes only the scenes it owns (:meth:`Shard.owns`),
    through the same padded group programs and keys as the whole batch, and holds the output
    folder beside the other shards (its own marker); the shard that finds every scene complete
    at its end writes ``batch.json`` (:meth:`_merge`).
    """

    def __init__(
        self,
        sources: list[str],
        out: Path,
        settings: BatchSettings = BatchSettings(),
        *,
        model: str | None = None,
        progress: Callable[[str], None] = _silent,
        cancel: threading.Event | None = None,
        resume: bool = False,
        shard: Shard = WHOLE,
    ):
        self.sources, self.out, self.settings = sources, Path(out), settings
        self.resume = resume
        self.shard = shard
        self.family, self.progress = model, progress
        self.cancel = cancel if cancel is not None else threading.Event()
        self._numbers: dict[int, int] = {}  # id(entry) -> its scene number
        self.entries: list[SceneEntry] = []
        self.groups = 0
        self.compile_seconds = 0.0
        self.started = time.perf_counter()
        self._partials: set[Path] = set()
        self._lock = threading.Lock()

    # ------------------------------------------------------------------------------ state

    def result(self, interrupted: bool = False) -> BatchResult:
        """The batch so far."""
        return BatchResult(
            entries=self.entries,
            groups=self.groups,
            devices=jax.device_count(),
            seconds=time.perf_counter() - self.started,
            compile_seconds=self.compile_seconds,
            interrupted=interrupted,
            shards=self.shard.count,
        )

    def write_summary(self, interrupted: bool = False) -> BatchResult:
        """``batch.json`` (not by a shard of several: :meth:`_merge` writes theirs)."""
        result = self.result(interrupted)
        if self.shard.count == 1:
            RunFolder(self.out).write_json(BATCH_FILE, result.as_json())
        return result

    def owns(self, entry: SceneEntry) -> bool:
        """This shard runs ``entry`` (always, in a batch of one shard)."""
        return self.shard.owns(self._numbers[id(entry)])

    def abandon(self) -> None:
        """Remove every run folder still being written (from any thread; the batch is then
        not to be continued)."""
        with self._lock:
            partials = list(self._partials)
        for path in partials:
            _remove(path)

    def _check(self) -> None:
        if self.cancel.is_set():
            raise _Stop

    # ------------------------------------------------------------------------------ run

    def run(self) -> BatchResult:
        """Sample and write every scene; raises :class:`BatchInterrupted` when cancelled."""
        with hold_output(self.out, self.shard):  # an interrupted batch leaves it marked
            return self._run()

    def _run(self) -> BatchResult:
        try:
            groups = self._load()
            for number, members in enumerate(groups.values(), start=1):
                self._check()
                self._run_group(number, len(groups), members)
            if self.shard.count > 1:
                return self._merge(groups)
        except _Stop:
            self.abandon()
            raise BatchInterrupted(self.write_summary(interrupted=True)) from None
        except BaseException as error:
            self.abandon()
            if _is_cancelled(error) and self.cancel.is_set():
                raise BatchInterrupted(self.write_summary(interrupted=True)) from None
            raise
        return self.write_summary()

    def _load(self) -> dict[str, list[tuple[SceneEntry, Any, Any]]]:
        self.entries = [SceneEntry(source) for source in expand_sources(self.sources)]
        self._numbers = {id(entry): number for number, entry in enumerate(self.entries)}
        groups: dict[str, list[tuple[SceneEntry, Any, Any]]] = {}
        for entry in self.entries:
            self._check()
            try:
                entry.scene = load_scene(entry.source)
                measurements = entry.scene.load_measurements()
                implausible = measurement_checks(entry.scene, measurements)
                require_plausible(implausible, self.settings.force)
                entry.forced = [found.record for found in implausible]
                posterior_model = build_model(entry.scene, measurements, self.family)
            except BadInputError as error:
                entry.error = str(error)
                self.progress(f"skipped {entry.source}: {error}")
                continue
            key = structure_key(posterior_model)
            groups.setdefault(key, []).append((entry, posterior_model, measurements))
        if not groups:
            first = self.entries[0] if self.entries else SceneEntry("", error="no scenes given")
            raise BadInputError(f"no scene could be run: {first.error}", field="SCENE")
        for entry, folder in zip(self.entries, _folder_names(self.entries), strict=True):
            entry.out = self.out / folder if entry.error is None else None
        self.groups = len(groups)
        ours = [entry.out.name for entry in self.entries if entry.out and self.owns(entry)]
        remove_stale_partials(self.out, ours)
        if self.resume:
            for entry, member_model, measurements in (m for g in groups.values() for m in g):
                if self.owns(entry):
                    self._keep_if_complete(entry, member_model, measurements)
            kept = sum(entry.done for entry in self.entries)
            self.progress(f"resume: {kept} scene(s) complete in {self.out}, kept")
        return groups

    def _keep_if_complete(self, entry: SceneEntry, model, measurements) -> None:
        """Mark ``entry`` done when its run folder is in place and this batch wrote it
        (its summary and bands are then the entry's).

        Raises:
            BadInputError: the folder holds a complete run of another scene, data or settings.
        """
        folder = entry.out
        run = RunFolder(folder)
        if not all(run.has(name) for name in (POSTERIOR_FILE, SUMMARY_FILE, BANDS_FILE)):
            return  # not there (a scene folder is renamed into place complete): run it
        require_complete(folder)
        try:
            summary, bands = run.summary(), run.bands()
        except BadInputError as error:
            raise BadInputError(
                f"cannot read the run to resume: {error.problem}", file=error.file
            ) from None
        settings = self.settings
        fingerprint = run_fingerprint(model, measurements)
        recorded = summary.get("fingerprint") or {}
        differences = [name for name, value in fingerprint.items() if recorded.get(name) != value]
        ours = {"model": model_name(model), "forced": entry.forced}
        differences += [name for name, value in ours.items() if summary.get(name) != value]
        ran = summary.get("settings") or {}
        differences += [
            f"--{name.replace('_', '-')}"
            for name in ("chains", "warmup", "draws", "seed", "target_accept")
            if ran.get(name) != getattr(settings, name)
        ]
        if differences:
            raise BadInputError(
                f"holds a complete run of another batch (differs in: {', '.join(differences)}); "
                "run the batch without --resume to replace it, or into another --out",
                file=folder,
                field="resume",
            )
        entry.summary = summary
        entry.tis = _tis_entry(bands)
        entry.done = True

    def _run_group(self, number: int, count: int, members: list) -> None:
        settings = self.settings
        first = members[0][1]
        datasets = [m.data for _, m, _ in members]
        if paddable(first):  # every member is (one structure key)
            datasets = pad_datasets(datasets)  # the whole group's shape, also on a resume
        padded = sum(d is not m.data for d, (_, m, _) in zip(datasets, members, strict=True))
        padded = f", {padded} padded to {row_count(datasets[0])} rows" if padded else ""
        ours = [index for index, (entry, _, _) in enumerate(members) if self.owns(entry)]
        todo = [index for index in ours if not members[index][0].done]
        kept = f", {len(ours) - len(todo)} complete already" if len(todo) < len(ours) else ""
        if self.shard.count > 1:
            kept += f", {len(ours)} of them in shard {self.shard}"
        self.progress(
            f"group {number}/{count}: {len(members)} scene(s){kept}, {model_name(first)}{padded}, "
            f"{settings.chains} chains x ({settings.warmup} warmup + {settings.draws} draws)"
        )
        if not todo:
            return
        group_size, members = len(members), [members[index] for index in todo]
        datasets = [datasets[index] for index in todo]
        program_model = dataclasses.replace(first, data=datasets[0])
        program = NutsProgram(
            program_model, warmup=settings.warmup, target_accept=settings.target_accept
        )
        keys = np.stack([chain_keys(settings.seed, 1, settings.chains)[0] for _ in members])
        output = program.run_many(  # this process's devices: the others run their own scenes
            stack_data(datasets),
            keys,
            settings.draws,
            mode=settings.mode,
            cancel=self.cancel,
            devices=jax.local_devices(),
        )
        self._check()
        self.compile_seconds += output.seconds["compile"]
        share = {k: v / len(members) for k, v in output.seconds.items()}
        options = {
            "chains": settings.chains,
            "warmup": settings.warmup,
            "draws": settings.draws,
            "seed": settings.seed,
            "dense_mass": True,
            "target_accept": settings.target_accept,
            "batch": {"scenes": group_size, "mode": settings.mode},
        }
        shapes: dict[str, dict[str, tuple]] = {}  # the sites of each data shape in the group
        jobs = []
        for index, (entry, member_model, measurements) in enumerate(members):
            sites = {k: v[index] for k, v in output.sites.items()}
            # only parameter sites come from the padded run: none may have a row axis
            shape = str(jax.tree_util.tree_map(np.shape, member_model.data))
            if shape not in shapes:
                shapes[shape] = _site_shapes(member_model, member_model.data)
            own = shapes[shape]
            if set(own) != set(sites) or any(v.shape[2:] != own[k] for k, v in sites.items()):
                raise RuntimeError(
                    f"scene {entry.scene.name}: the padded run's sites differ in shape from "
                    "the scene's own model (a per-row site cannot be padded)"
                )
            draws = nuts_draws(
                sites, {k: v[index] for k, v in output.stats.items()}, options, dict(share)
            )
            begun = time.perf_counter() - share["sampling"] - share["compile"]
            jobs.append((entry, member_model, measurements, draws, begun))
        self._write_all(jobs)

    # ------------------------------------------------------------------------------ folders

    def _write_all(self, jobs: list) -> None:
        """Every run folder of a group, one after another.

        Not side by side: NumPyro keeps one effect-handler stack for the whole process, so
        two threads tracing the posterior predictive at once corrupt each other's traces; the
        writes are a small part of a batch (≈ 1 s per scene, against its sampling)."""
        for job in jobs:
            self._write(*job)

    def _write(self, entry: SceneEntry, model, measurements, draws, begun: float) -> None:
        """One scene's run folder: written under a temporary name, renamed into place."""
        self._check()
        target = entry.out
        partial = target.parent / f".{target.name}{PARTIAL_MARK}{os.getpid()}"
        with self._lock:
            self._partials.add(partial)
        try:
            _remove(partial)
            run = complete_run(  # no NUTS refits of error-model variants per scene
                model,
                measurements,
                draws,
                self.settings.seed,
                partial,
                begun,
                forced=entry.forced,
                refit=False,
            )
            self._publish(partial, target)  # complete: kept even if the batch is cancelled now
        finally:
            _remove(partial)
            with self._lock:
                self._partials.discard(partial)
        entry.summary = run.summary
        entry.tis = _tis_entry(run.bands)
        entry.done = True
        self.progress(f"  {entry.scene.name}: {entry.out}")

    def _merge(self, groups: dict[str, list]) -> BatchResult:
        """A shard's end: when the other shards' scenes are complete in ``out`` too (checked
        as ``--resume`` checks a folder), ``batch.json`` of the whole batch; else its own
        scenes' result, ``merged`` False (the last shard to finish writes ``batch.json``)."""
        for entry, member_model, measurements in (m for g in groups.values() for m in g):
            if not entry.done:
                with contextlib.suppress(BadInputError):  # another run: not complete (yet)
                    self._keep_if_complete(entry, member_model, measurements)
        result = self.result()
        if all(entry.done for entry in self.entries if entry.error is None):
            RunFolder(self.out).write_json(BATCH_FILE, result.as_json())
            return result
        missing = sum(not e.done and e.error is None for e in self.entries)
        self.progress(
            f"shard {self.shard}: {missing} scene(s) of other shards not complete in {self.out} "
            "yet; the last shard to finish writes batch.json"
        )
        result.entries = [entry for entry in self.entries if self.owns(entry)]
        result.merged = False
        return result

    def _publish(self, partial: Path, target: Path) -> None:
        """Rename the complete folder ``partial`` to ``target`` (an earlier run's folder there
        is replaced)."""
        if target.exists() or target.is_symlink():
            old = target.parent / f".{target.name}{OLD_MARK}{os.getpid()}"
            with self._lock:
                self._partials.add(old)
            _remove(old)
            os.replace(target, old)
            os.replace(partial, target)
            _remove(old)
            with self._lock:
                self._partials.discard(old)
        else:
            os.replace(partial, target)


def hold_output(out: Path, shard: Shard = WHOLE, option: str = "out"):
    """Hold ``out`` for a batch (one writer), or for one of its shards (one writer per
    shard, beside the others: :mod:`brdf_infer._internal.outlock`)."""
    if shard.count == 1:
        return writing(out, "batch", option=option)
    marker = shard_lock_file(shard.index, shard.count)
    return writing(out, f"batch --shard {shard}", option=option, marker=marker)


class _Stop(Exception):
    """The batch's cancel event is set."""


def _is_cancelled(error: BaseException) -> bool:
    return isinstance(error, Cancelled)


def run_batch(
    sources: list[str],
    out: Path,
    settings: BatchSettings = BatchSettings(),
    *,
    model: str | None = None,
    progress: Callable[[str], None] = _silent,
    cancel: threading.Event | None = None,
    resume: bool = False,
    shard: Shard = WHOLE,
) -> BatchResult:
    """Sample the posterior of every scene in ``sources`` (names, TOML paths or globs) into
    ``out/<scene>/`` and write ``out/batch.json`` (module docstring).

    Args:
        model: the family of every scene (default: each scene's ``[model] family``).
        cancel: when set, the batch stops between sampling chunks and between run folders.
        resume: keep the scenes whose run folders this batch already wrote (module docstring).
        shard: the scenes to run, for a batch over several shards (:class:`Batch`).

    Raises:
        BadInputError: settings out of range, another process writing ``out``, or (``resume``)
            a run folder of another run (a scene's own errors are reported in its entry).
        BatchInterrupted: ``cancel`` was set; the complete run folders stay, no partial one,
            and ``batch.json`` lists every scene (the unfinished ones as interrupted).
    """
    ensure_float64()
    batch = Batch(
        sources,
        out,
        settings,
        model=model,
        progress=progress,
        cancel=cancel,
        resume=resume,
        shard=shard,
    )
    return batch.run()
