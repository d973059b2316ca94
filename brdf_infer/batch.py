"""Posteriors of many scenes in one compiled program: ``brdf-infer batch``.

Scenes are grouped by model structure: the same family, error model, priors and model options
give the same compiled NUTS program with the data as its argument
(:class:`brdf_infer.posterior.NutsProgram`), so each group is compiled once and all its scenes
run through it (``run_many``: one data set per thread on a single CPU; vmapped with the scene
axis sharded over every device JAX sees otherwise). Scenes of unequal size share a group: their
data are padded to the group's largest row count and largest number of samples, calibration
groups and rotation settings, the padding rows carrying a mask that removes them from the likelihood
exactly (:mod:`brdf_infer.posterior._padding`); only scenes with latent angles (a sampled
variable per row) group by their exact shape. Each scene's run folder is exactly what
``brdf-infer posterior`` writes (``report``, ``tis --run`` and ``export --run`` read it),
computed from the scene's own unpadded model and rows, and each scene's chains use the keys
``posterior --seed S`` would: on one CPU device a scene that needed no padding (the largest
of its group, or any scene of a group of equal shapes) has the draws of its own ``posterior``
run, bit for bit; a padded scene samples the same posterior (the same log density, to
rounding) through a program of another shape, so its draws agree in distribution only.

The run folders of a group are written one after another, each under a
temporary name beside its place and renamed into place when complete, so a folder under its
scene's name is always a complete run. A batch stops within seconds when cancelled
(:func:`run_batch` ``cancel``; ``brdf-infer batch`` on SIGINT or SIGTERM:
:func:`run_batch_until_signalled`), keeping the folders that were complete and no partial one;
killed outright, it leaves the same (and half-written folders under temporary names, which the
next batch into the folder removes). The output folder has one writer at a time
(:mod:`brdf_infer._outlock`) and stays marked incomplete until a batch into it finishes.

``resume=True`` (``brdf-infer batch --resume``) keeps every scene whose run folder is in place
and was written by the same scene text, rows, model options, family and NUTS settings (the
``fingerprint`` and ``settings`` of its ``summary.json``), and runs the rest; a folder of another
run is refused, not replaced. The rest of a group run through the program of the whole group
(padded to the same shape, the same keys), so on one CPU device the resumed scenes get the
draws an uninterrupted batch gives them, bit for bit (in vmap mode, to rounding).

A scene that fails to load or validate is reported with its error and skipped; it never takes
the batch down. So is a scene whose rows fail a plausibility check (values that look like
percent, angles that look like radians; :mod:`brdf_infer.plausibility`), unless
``BatchSettings(force=True)``: then it runs and its verdict names the check.
"""

from __future__ import annotations

import dataclasses
import glob
import hashlib
import json
import os
import shutil
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jax
import numpy as np

from brdf_infer._atomic import atomic_write_json
from brdf_infer._outlock import note_written, require_complete, writing
from brdf_infer.errors import BadInputError
from brdf_infer.plausibility import measurement_checks, require_plausible
from brdf_infer.posterior import (
    BANDS_FILE,
    POSTERIOR_FILE,
    SUMMARY_FILE,
    Cancelled,
    FlatPotential,
    NutsProgram,
    build_model,
    chain_keys,
    complete_run,
    model_name,
    nuts_draws,
    pad_datasets,
    paddable,
    padded_signature,
    row_count,
    run_fingerprint,
    stack_data,
)
from brdf_infer.scene import Scene, load_scene
from brdf_infer.settings import BatchSettings

BATCH_FILE = "batch.json"
PARTIAL_MARK = ".partial-"  # out/.<scene>.partial-<pid>: a run folder being written
OLD_MARK = ".old-"  # out/.<scene>.old-<pid>: the folder a complete one is replacing
GRACE_SECONDS = 3.0  # after a signal, how long the batch may take to stop on its own
INTERRUPTED = "interrupted before its run was complete"


def _silent(message: str) -> None:
    del message


@dataclass
class SceneEntry:
    """One scene of a batch: where it came from, and its run or its error.

    Attributes:
        done: its run folder is complete and in place.
    """

    source: str
    scene: Scene | None = None
    out: Path | None = None
    summary: dict[str, Any] | None = None
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
    (``interrupted``: the batch was cancelled; entries not ``done`` have no run folder)."""

    entries: list[SceneEntry]
    groups: int
    devices: int
    seconds: float
    compile_seconds: float
    interrupted: bool = False

    @property
    def complete(self) -> int:
        """Scenes whose run folder is complete."""
        return sum(entry.done for entry in self.entries)

    def as_json(self) -> dict[str, Any]:
        return {
            "scenes": [entry.as_json() for entry in self.entries],
            "groups": self.groups,
            "devices": self.devices,
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
        self.hard = False  # the batch's threads still run: end the process with os._exit

    @property
    def exit_code(self) -> int:
        """128 + the signal number (130 for SIGINT, 143 for SIGTERM); 130 without a signal."""
        return 128 + (self.signum if self.signum is not None else signal.SIGINT)

    def message(self, out: Path) -> str:
        """One line: what stopped the batch and how many scene folders are complete."""
        name = signal.Signals(self.signum).name if self.signum is not None else "cancelled"
        total = sum(entry.error is None for entry in self.result.entries)
        return (
            f"interrupted ({name}): {self.result.complete} of {total} scene(s) complete in "
            f"{out} (listed in {BATCH_FILE}); no partial folder left (continue with --resume)"
        )


def expand_sources(patterns: list[str]) -> list[str]:
    """Scene names and TOML paths from names, paths and glob patterns (sorted per pattern;
    a pattern that matches nothing is kept, so that loading it reports it)."""
    sources: list[str] = []
    for pattern in patterns:
        matches = sorted(glob.glob(pattern)) if glob.has_magic(pattern) else []
        sources += matches or [pattern]
    return list(dict.fromkeys(sources))


def structure_key(model) -> str:
    """What must agree for two scenes to share one compiled program: the family, the model's
    options (error model, priors, folding and constants, free parameters, reparametrisation)
    and the data's tree structure and shapes — the row count and the number of samples,
    calibration groups and rotation settings left out where the data can be padded to one shape
    (:func:`brdf_infer.posterior._padding.paddable`)."""
    scene = model.scene
    options: dict[str, Any] = {
        "family": model_name(model),
        "errors": scene.errors.describe(),
        "fold": scene.model.fold,
        "constants": scene.model.constants._asdict(),
        "priors": {k: dataclasses.asdict(v) for k, v in scene.priors.items()},
        "free": list(scene.free_parameters),
        "reparametrised": model.whiten,
    }
    if paddable(model):
        options["padded"] = padded_signature(model.data)
    else:
        leaves, tree = jax.tree_util.tree_flatten(model.data)
        options["tree"] = str(tree)
        options["shapes"] = [(tuple(np.shape(x)), str(np.asarray(x).dtype)) for x in leaves]
    return hashlib.sha256(json.dumps(options, sort_keys=True, default=str).encode()).hexdigest()


def _folder_names(entries: list[SceneEntry]) -> list[str]:
    """One folder name per scene: its name, made unique with a suffix where names repeat."""
    names, seen = [], {}
    for entry in entries:
        base = entry.scene.name if entry.scene is not None else Path(entry.source).stem
        seen[base] = seen.get(base, 0) + 1
        names.append(base if seen[base] == 1 else f"{base}-{seen[base]}")
    return names


def _site_shapes(model, data) -> dict[str, tuple]:
    """The shape of every site of one draw of ``model`` on ``data`` (traced, not run)."""
    flat = FlatPotential(model)
    shapes = jax.eval_shape(flat.constrain, jax.ShapeDtypeStruct((flat.dimension,), float), data)
    return {name: tuple(leaf.shape) for name, leaf in shapes.items()}


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_partials(out: Path) -> list[Path]:
    """Remove run folders left half-written in ``out`` by a batch that was killed outright
    (SIGKILL, power loss): ``.<scene>.partial-<pid>`` (and ``.<scene>.old-<pid>``, the folder
    it was replacing) of a process that no longer runs."""
    removed = []
    if not out.is_dir():
        return removed
    for mark in (PARTIAL_MARK, OLD_MARK):
        for path in out.glob(f".*{mark}*"):
            pid = path.name.rsplit(mark, 1)[-1]
            if pid.isdigit() and (int(pid) == os.getpid() or not _pid_alive(int(pid))):
                _remove(path)
                removed.append(path)
    return removed


class Batch:
    """One batch run (:func:`run_batch`), its state readable from another thread: the entries,
    the groups and the run folders being written."""

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
    ):
        self.sources, self.out, self.settings = sources, Path(out), settings
        self.resume = resume
        self.family, self.progress = model, progress
        self.cancel = cancel if cancel is not None else threading.Event()
        self.entries: list[SceneEntry] = []
        self.groups = 0
        self.compile_seconds = 0.0
        self.started = time.perf_counter()
        self._partials: set[Path] = set()
        self._lock = threading.Lock()

    # ------------------------------------------------------------------------------ state

    def result(self, interrupted: bool = False) -> BatchResult:
        return BatchResult(
            entries=self.entries,
            groups=self.groups,
            devices=jax.device_count(),
            seconds=time.perf_counter() - self.started,
            compile_seconds=self.compile_seconds,
            interrupted=interrupted,
        )

    def write_summary(self, interrupted: bool = False) -> BatchResult:
        result = self.result(interrupted)
        self.out.mkdir(parents=True, exist_ok=True)
        atomic_write_json(self.out / BATCH_FILE, result.as_json())
        return result

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
        with writing(self.out, "batch"):  # one writer; an interrupted batch leaves it marked
            return self._run()

    def _run(self) -> BatchResult:
        try:
            groups = self._load()
            for number, members in enumerate(groups.values(), start=1):
                self._check()
                self._run_group(number, len(groups), members)
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
        remove_stale_partials(self.out)
        if self.resume:
            for entry, member_model, measurements in (m for g in groups.values() for m in g):
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
        files = [folder / name for name in (POSTERIOR_FILE, SUMMARY_FILE, BANDS_FILE)]
        if not all(path.is_file() for path in files):
            return  # not there (a scene folder is renamed into place complete): run it
        require_complete(folder)
        try:
            summary = json.loads(files[1].read_text())
            bands = json.loads(files[2].read_text())
        except (OSError, ValueError) as error:
            raise BadInputError(f"cannot read the run to resume: {error}", file=folder) from None
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
        todo = [index for index, (entry, _, _) in enumerate(members) if not entry.done]
        kept = f", {len(members) - len(todo)} complete already" if len(todo) < len(members) else ""
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
        output = program.run_many(
            stack_data(datasets), keys, settings.draws, mode=settings.mode, cancel=self.cancel
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
            run = complete_run(
                model, measurements, draws, self.settings.seed, partial, begun, forced=entry.forced
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
        note_written(target)


def _tis_entry(bands: dict) -> dict[str, list] | None:
    """The TIS band of a run's bands, as a batch entry lists it."""
    band = bands.get("tis")
    return None if band is None else {k: band[k] for k in ("theta_i_deg", "median", "lo95", "hi95")}


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
) -> BatchResult:
    """Sample the posterior of every scene in ``sources`` (names, TOML paths or globs) into
    ``out/<scene>/`` and write ``out/batch.json`` (module docstring).

    Args:
        model: the family of every scene (default: each scene's ``[model] family``).
        cancel: when set, the batch stops between sampling chunks and between run folders.
        resume: keep the scenes whose run folders this batch already wrote (module docstring).

    Raises:
        BadInputError: settings out of range, another process writing ``out``, or (``resume``)
            a run folder of another run (a scene's own errors are reported in its entry).
        BatchInterrupted: ``cancel`` was set; the complete run folders stay, no partial one,
            and ``batch.json`` lists every scene (the unfinished ones as interrupted).
    """
    batch = Batch(
        sources, out, settings, model=model, progress=progress, cancel=cancel, resume=resume
    )
    return batch.run()


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
    batch = Batch(sources, out, settings, model=model, progress=progress, resume=resume)
    if threading.current_thread() is not threading.main_thread():  # no signals here
        return batch.run()
    outcome: dict[str, Any] = {}
    received: list[tuple[int, float]] = []

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
    if worker.is_alive():  # did not stop in time: stop it from here
        interrupted = BatchInterrupted(batch.write_summary(interrupted=True), received[0][0])
        batch.abandon()  # last, so that the process ends right after (a writer may still run)
        interrupted.hard = True
        raise interrupted
    error = outcome.get("error")
    if isinstance(error, BatchInterrupted) or (error is None and received):
        result = error.result if error is not None else outcome["result"]
        raise BatchInterrupted(result, received[0][0] if received else None)
    if error is not None:
        raise error
    return outcome["result"]
