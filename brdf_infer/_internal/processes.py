"""Which process of a batch over several processes runs which scene (pure logic: nothing here
starts JAX).

A batch over ``N`` processes (``brdf-infer batch --num-processes N``) gives scene ``k`` of the
expanded scene list (0-based, in the order the sources name them, scenes that fail to load
included) to process ``k mod N``: every process computes the same list from the same command
line, so each scene's run folder has exactly one owner, known to all without a message.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass

from brdf_infer.errors import BadInputError

PEER_TIMEOUT = 60.0  # [s] no heartbeat for this long: a process is taken as failed


@dataclass(frozen=True)
class Processes:
    """The processes of one batch and this one's place among them.

    Attributes:
        count: the number of processes (1: a batch in this process alone).
        index: this process's id, 0 to ``count - 1`` (0 writes ``batch.json``).
        coordinator: ``HOST:PORT`` of ``jax.distributed``'s coordinator (process 0); None:
            JAX finds it itself (under SLURM: the first host of the job step).
        peer_timeout: [s] a process that sends no heartbeat for this long is taken as failed.
    """

    count: int = 1
    index: int = 0
    coordinator: str | None = None
    peer_timeout: float = PEER_TIMEOUT

    @property
    def several(self) -> bool:
        """More than one process."""
        return self.count > 1

    def owner(self, scene: int) -> int:
        """The process that runs scene number ``scene`` (0-based) and writes its folder."""
        return scene % self.count

    def owns(self, scene: int) -> bool:
        """This process runs scene number ``scene``."""
        return self.owner(scene) == self.index


def resolve_processes(
    coordinator: str | None,
    num_processes: int,
    process_id: int | None,
    peer_timeout: float = PEER_TIMEOUT,
    environ: Mapping[str, str] | None = None,
) -> Processes:
    """The processes of a batch from its options, the missing ones from the environment:
    ``process_id`` from ``SLURM_PROCID`` (what ``srun`` sets per task), ``coordinator`` from
    ``JAX_COORDINATOR_ADDRESS``, else left to JAX's SLURM detection when ``SLURM_JOB_ID`` is set.

    Raises:
        BadInputError: a count below 1, an id out of range or missing, no coordinator, a
            coordinator not ``HOST:PORT``, or a timeout not above 0 (one line, the option named).
    """
    environ = os.environ if environ is None else environ
    if num_processes < 1:
        raise BadInputError(f"must be at least 1, got {num_processes}", field="num_processes")
    if not peer_timeout > 0:
        raise BadInputError(f"must be above 0 s, got {peer_timeout:g}", field="peer_timeout")
    if process_id is None and num_processes > 1:
        slurm = environ.get("SLURM_PROCID", "")
        if not slurm.isdigit():
            raise BadInputError(
                f"is needed with --num-processes {num_processes} (or SLURM_PROCID, as srun "
                "sets it)",
                field="process_id",
            )
        process_id = int(slurm)
    process_id = 0 if process_id is None else process_id
    if not 0 <= process_id < num_processes:
        raise BadInputError(
            f"{process_id} is out of range for {num_processes} process(es) "
            f"(0 to {num_processes - 1})",
            field="process_id",
        )
    if num_processes == 1:
        return Processes(peer_timeout=peer_timeout)
    coordinator = coordinator or environ.get("JAX_COORDINATOR_ADDRESS") or None
    if coordinator is None and "SLURM_JOB_ID" not in environ:
        raise BadInputError(
            f"HOST:PORT of process 0 is needed with --num-processes {num_processes} "
            "(or JAX_COORDINATOR_ADDRESS, or a SLURM job step)",
            field="coordinator",
        )
    if coordinator is not None:
        _check_address(coordinator)
    return Processes(num_processes, process_id, coordinator, peer_timeout)


def _check_address(address: str) -> None:
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise BadInputError(
            f"{address!r} is not HOST:PORT (a port from 1 to 65535)", field="coordinator"
        )
