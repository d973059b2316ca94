"""Wall time of consecutive steps of a job, by name (the run's ``seconds`` records)."""

from __future__ import annotations

import time


class StepClock:
    """Wall time of consecutive steps [s], by name: each :meth:`lap` ends a step begun at the
    previous lap (or at the clock's creation)."""

    def __init__(self):
        self.steps: dict[str, float] = {}
        self._last = time.perf_counter()

    def lap(self, name: str) -> None:
        """End the step ``name`` now (a name given again adds to its time)."""
        now = time.perf_counter()
        self.steps[name] = self.steps.get(name, 0.0) + now - self._last
        self._last = now
