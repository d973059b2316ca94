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
(:mod:`brdf_infer._internal.outlock`) and stays marked incomplete until a batch into it finishes.

``resume=True`` (``brdf-infer batch --resume``) keeps every scene whose run folder is in place
and was written by the same scene text, rows, model options, family and NUTS settings (the
``fingerprint`` and ``settings`` of its ``summary.json``), and runs the rest; a folder of another
run is refused, not replaced. The rest of a group run through the program of the whole group
(padded to the same shape, the same keys), so on one CPU device the resumed scenes get the
draws an uninterrupted batch gives them, bit for bit (in vmap mode, to rounding).

In shards (``shard``: :class:`Shard`, ``brdf-infer batch --shard
K/N``, in as many independent processes, on as many hosts as wanted) scene ``k`` belongs to
shard ``k mod N``: every shard loads and groups every scene and runs its own through the
group's program, so each run folder is written once, by its shard, with the draws of the whole
batch in one process. The shards share nothing but the output folder; the one that finds every
scene complete at its end writes ``batch.json`` (so does a ``--resume`` without ``--shard``).

A scene that fails to load or validate is reported with its error and skipped; it never takes
the batch down. So is a scene whose rows fail a plausibility check (values that look like
percent, angles that look like radians; :mod:`brdf_infer.verdict.plausibility`), unless
``BatchSettings(force=True)``: then it runs and its verdict names the check.
"""

from brdf_infer._internal.shards import Shard
from brdf_infer.scene.settings import (
    BatchSettings as BatchSettings,
)  # as before: bench imports it here
from brdf_infer.workflow.batch._batch import Batch, hold_output, run_batch
from brdf_infer.workflow.batch._entries import (
    BATCH_FILE,
    INTERRUPTED,
    BatchInterrupted,
    BatchResult,
    SceneEntry,
)
from brdf_infer.workflow.batch._folders import OLD_MARK, PARTIAL_MARK, remove_stale_partials
from brdf_infer.workflow.batch._groups import expand_sources, structure_key
from brdf_infer.workflow.batch._signals import GRACE_SECONDS, run_batch_until_signalled

__all__ = [
    "BATCH_FILE",
    "GRACE_SECONDS",
    "INTERRUPTED",
    "OLD_MARK",
    "PARTIAL_MARK",
    "Batch",
    "BatchInterrupted",
    "BatchResult",
    "SceneEntry",
    "Shard",
    "expand_sources",
    "hold_output",
    "remove_stale_partials",
    "run_batch",
    "run_batch_until_signalled",
    "structure_key",
]
