"""Posteriors of many scenes in one compiled program: ``brdf-infer batch``.

Scenes are grouped by model structure: the same family, error model, priors, model options and
data shapes (row count, samples, series, noise layout) give the same compiled NUTS program
with the data as its argument (:class:`brdf_infer.posterior.NutsProgram`), so each group is
compiled once and all its scenes run through it (``run_many``: one data set per thread on a
single CPU; vmapped with the scene axis sharded over every device JAX sees otherwise). Each
scene's run folder is exactly what ``brdf-infer posterior`` writes (``report``, ``tis --run``
and ``export --run`` read it), and each scene's chains use the keys ``posterior --seed S``
would, so on one CPU device a scene's draws are those of its own ``posterior`` run.

A scene that fails to load or validate is reported with its error and skipped; it never takes
the batch down.
"""

from __future__ import annotations

import dataclasses
import glob
import hashlib
import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jax
import numpy as np

from brdf_infer._atomic import atomic_write_json
from brdf_infer.errors import BadInputError
from brdf_infer.posterior import NutsProgram, build_model, chain_keys, model_name
from brdf_infer.posterior._nuts import stack_data
from brdf_infer.posterior._run import complete_run
from brdf_infer.posterior._samplers import nuts_draws
from brdf_infer.scene import Scene, load_scene

BATCH_FILE = "batch.json"


def _silent(message: str) -> None:
    del message


@dataclass(frozen=True)
class BatchSettings:
    """NUTS settings shared by every scene of a batch (``seed``: each scene's chains get the
    keys ``posterior --seed`` gives them)."""

    chains: int = 4
    draws: int = 1000
    warmup: int = 1000
    seed: int = 0
    target_accept: float = 0.8
    mode: str = "auto"

    def check(self) -> None:
        """Raises BadInputError naming the option that is out of range."""
        for name in ("chains", "draws"):
            if getattr(self, name) < 1:
                raise BadInputError(
                    f"must be at least 1, got {getattr(self, name)}", field=f"--{name}"
                )
        if self.warmup < 0:
            raise BadInputError(f"must be >= 0, got {self.warmup}", field="--warmup")
        if not 0 < self.target_accept < 1:
            raise BadInputError(
                f"must lie in (0, 1), got {self.target_accept}", field="--target-accept"
            )
        if self.mode not in ("auto", "threads", "vmap"):
            raise BadInputError(f"unknown mode {self.mode!r} (auto, threads, vmap)", field="--mode")


@dataclass
class SceneEntry:
    """One scene of a batch: where it came from, and its run or its error."""

    source: str
    scene: Scene | None = None
    out: Path | None = None
    summary: dict[str, Any] | None = None
    tis: dict[str, list] | None = None
    error: str | None = None

    def as_json(self) -> dict[str, Any]:
        diagnostics = (self.summary or {}).get("diagnostics", {})
        ess = [diagnostics.get("ess_bulk_min"), diagnostics.get("ess_tail_min")]
        return {
            "scene": self.scene.name if self.scene is not None else self.source,
            "source": self.source,
            "out": None if self.out is None else str(self.out),
            "model": None if self.summary is None else self.summary["model"],
            "r_hat_max": diagnostics.get("r_hat_max"),
            "ess_min": None if None in ess else min(ess),
            "divergences": diagnostics.get("divergences"),
            "tis": self.tis,
            "error": self.error,
        }


@dataclass
class BatchResult:
    """Every scene's entry, the number of compiled groups and devices, and the wall time."""

    entries: list[SceneEntry]
    groups: int
    devices: int
    seconds: float
    compile_seconds: float

    def as_json(self) -> dict[str, Any]:
        return {
            "scenes": [entry.as_json() for entry in self.entries],
            "groups": self.groups,
            "devices": self.devices,
            "seconds": self.seconds,
            "compile_seconds": self.compile_seconds,
        }


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
    and the data's tree structure and shapes."""
    scene = model.scene
    leaves, tree = jax.tree_util.tree_flatten(model.data)
    options = {
        "family": model_name(model),
        "errors": scene.errors.describe(),
        "fold": scene.model.fold,
        "constants": scene.model.constants._asdict(),
        "priors": {k: dataclasses.asdict(v) for k, v in scene.priors.items()},
        "free": list(scene.free_parameters),
        "reparametrised": model.whiten,
        "tree": str(tree),
        "shapes": [(tuple(np.shape(x)), str(np.asarray(x).dtype)) for x in leaves],
    }
    return hashlib.sha256(json.dumps(options, sort_keys=True, default=str).encode()).hexdigest()


def _folder_names(entries: list[SceneEntry]) -> list[str]:
    """One folder name per scene: its name, made unique with a suffix where names repeat."""
    names, seen = [], {}
    for entry in entries:
        base = entry.scene.name if entry.scene is not None else Path(entry.source).stem
        seen[base] = seen.get(base, 0) + 1
        names.append(base if seen[base] == 1 else f"{base}-{seen[base]}")
    return names


def run_batch(
    sources: list[str],
    out: Path,
    settings: BatchSettings = BatchSettings(),
    *,
    model: str | None = None,
    progress: Callable[[str], None] = _silent,
) -> BatchResult:
    """Sample the posterior of every scene in ``sources`` (names, TOML paths or globs) into
    ``out/<scene>/`` and write ``out/batch.json`` (module docstring).

    Args:
        model: the family of every scene (default: each scene's ``[model] family``).

    Raises:
        BadInputError: settings out of range (a scene's own errors are reported in its entry).
    """
    settings.check()
    started = time.perf_counter()
    entries = [SceneEntry(source) for source in expand_sources(sources)]
    groups: dict[str, list[tuple[SceneEntry, Any, Any]]] = {}
    for entry in entries:
        try:
            entry.scene = load_scene(entry.source)
            measurements = entry.scene.load_measurements()
            posterior_model = build_model(entry.scene, measurements, model)
        except BadInputError as error:
            entry.error = str(error)
            progress(f"skipped {entry.source}: {error}")
            continue
        key = structure_key(posterior_model)
        groups.setdefault(key, []).append((entry, posterior_model, measurements))
    if not groups:
        first = entries[0] if entries else SceneEntry("", error="no scenes given")
        raise BadInputError(f"no scene could be run: {first.error}", field="SCENE")
    for entry, folder in zip(entries, _folder_names(entries), strict=True):
        entry.out = out / folder if entry.error is None else None
    compile_seconds = 0.0
    for number, members in enumerate(groups.values(), start=1):
        first = members[0][1]
        progress(
            f"group {number}/{len(groups)}: {len(members)} scene(s), {model_name(first)}, "
            f"{settings.chains} chains x ({settings.warmup} warmup + {settings.draws} draws)"
        )
        program = NutsProgram(first, warmup=settings.warmup, target_accept=settings.target_accept)
        datasets = stack_data([m.data for _, m, _ in members])
        keys = np.stack([chain_keys(settings.seed, 1, settings.chains)[0] for _ in members])
        output = program.run_many(datasets, keys, settings.draws, mode=settings.mode)
        compile_seconds += output.seconds["compile"]
        share = {k: v / len(members) for k, v in output.seconds.items()}
        options = {
            "chains": settings.chains,
            "warmup": settings.warmup,
            "draws": settings.draws,
            "seed": settings.seed,
            "dense_mass": True,
            "target_accept": settings.target_accept,
            "batch": {"scenes": len(members), "mode": settings.mode},
        }
        for index, (entry, member_model, measurements) in enumerate(members):
            draws = nuts_draws(
                {k: v[index] for k, v in output.sites.items()},
                {k: v[index] for k, v in output.stats.items()},
                options,
                dict(share),
            )
            begun = time.perf_counter() - share["sampling"] - share["compile"]
            run = complete_run(member_model, measurements, draws, settings.seed, entry.out, begun)
            entry.summary = run.summary
            band = run.bands.get("tis")
            entry.tis = (
                None
                if band is None
                else {k: band[k] for k in ("theta_i_deg", "median", "lo95", "hi95")}
            )
            progress(f"  {entry.scene.name}: {entry.out}")
    result = BatchResult(
        entries=entries,
        groups=len(groups),
        devices=jax.device_count(),
        seconds=time.perf_counter() - started,
        compile_seconds=compile_seconds,
    )
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(out / BATCH_FILE, result.as_json())
    return result
