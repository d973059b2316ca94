"""The checks every record of NUTS settings shares (chains, draws, warmup, target acceptance)."""

from __future__ import annotations

from typing import Protocol

from brdf_infer.errors import BadInputError


class NutsSettings(Protocol):
    chains: int
    draws: int
    warmup: int
    target_accept: float


def check_nuts_settings(settings: NutsSettings) -> None:
    """Raises BadInputError naming the option (``--chains``, ``--draws``, ``--warmup``,
    ``--target-accept``) that is out of range."""
    for name in ("chains", "draws"):
        if getattr(settings, name) < 1:
            raise BadInputError(
                f"must be at least 1, got {getattr(settings, name)}", field=f"--{name}"
            )
    if settings.warmup < 0:
        raise BadInputError(f"must be >= 0, got {settings.warmup}", field="--warmup")
    if not 0 < settings.target_accept < 1:
        raise BadInputError(
            f"must lie in (0, 1), got {settings.target_accept}", field="--target-accept"
        )
