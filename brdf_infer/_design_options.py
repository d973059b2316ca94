"""How ``brdf-infer design`` estimates (its defaults and checks), without importing JAX, so
that building the command line stays light."""

from __future__ import annotations

from dataclasses import dataclass

from brdf_infer.errors import BadInputError


@dataclass(frozen=True)
class DesignOptions:
    """How the expectation is estimated.

    Attributes:
        draws: posterior draws used (evenly thinned from the run) [-].
        simulations: simulated outcomes J per candidate set [-].
        budget: rows chosen together (K).
        seed: random seed of the simulated outcomes.
    """

    draws: int = 1000
    simulations: int = 128
    budget: int = 3
    seed: int = 0

    def check(self) -> None:
        """Raises BadInputError naming the option out of range."""
        for name, low, high in (("draws", 50, 100000), ("simulations", 8, 4096), ("budget", 1, 10)):
            value = getattr(self, name)
            if not low <= value <= high:
                raise BadInputError(f"expected {low}..{high}, got {value}", field=f"--{name}")
