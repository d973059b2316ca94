"""Which scenes of a batch this process runs (pure logic: nothing here starts JAX).

``brdf-infer batch --shard K/N`` runs scenes ``K``, ``K + N``, ``K + 2N``, … of the expanded
scene list (0-based, in the order the sources name them, scenes that fail to load included):
every shard computes the same list from the same command line, so each scene's run folder has
exactly one shard, known to all without a message. ``--shard slurm`` takes ``K`` and ``N``
from ``SLURM_PROCID`` and ``SLURM_NTASKS`` (what ``srun`` sets for each task).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass

from brdf_infer.errors import BadInputError


@dataclass(frozen=True)
class Shard:
    """Shard ``index`` of ``count`` (``count`` 1: the whole batch)."""

    index: int = 0
    count: int = 1

    def owns(self, scene: int) -> bool:
        """This shard runs scene number ``scene`` (0-based) and writes its folder."""
        return scene % self.count == self.index

    def __str__(self) -> str:
        return f"{self.index}/{self.count}"


WHOLE = Shard()  # the whole batch, in one process


def resolve_shard(text: str | None, environ: Mapping[str, str] | None = None) -> Shard:
    """The shard that ``--shard`` names: ``K/N``, ``slurm`` (from the environment), or None
    (the whole batch).

    Raises:
        BadInputError: not ``K/N`` with ``0 <= K < N``, or ``slurm`` outside a SLURM task.
    """
    if text is None:
        return WHOLE
    environ = os.environ if environ is None else environ
    if text == "slurm":
        index, count = environ.get("SLURM_PROCID", ""), environ.get("SLURM_NTASKS", "")
        if not (index.isdigit() and count.isdigit()):
            raise BadInputError(
                "slurm needs SLURM_PROCID and SLURM_NTASKS (run it under srun)", field="shard"
            )
    else:
        index, _, count = text.partition("/")
    if not (index.isdigit() and count.isdigit() and int(index) < int(count)):
        raise BadInputError(f"{index}/{count} is not K/N with 0 <= K < N", field="shard")
    return Shard(int(index), int(count))
