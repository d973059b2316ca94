"""What an export is made from (:class:`Source`: one parameter set or a posterior run) and the
files it writes (the module docstring of :mod:`._files` says what each means)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from brdf_infer.model import ModelFamily
from brdf_infer.params import HemisphereConstants, Params

_BAND_QUANTILES = {"lower95": 0.025, "median": 0.5, "upper95": 0.975}


@dataclass(frozen=True)
class Source:
    """Where the exported BRDF comes from.

    Attributes:
        label: the parameter set's name or the run folder, for the file comments.
        params: one parameter set (scalar fields) or every posterior draw (1-D fields).
        from_run: ``params`` holds posterior draws.
        fold: the hemisphere BRDF includes Eq. (10) (the article's Table 3 does; False: the
            physical BRDF; always False with ``family``).
        constants: Δφ and folding constants (None with ``family``).
        scene: the scene's name, for the file comments.
        family: a posterior run of another model family (``params`` is then None and
            ``physical`` holds the draws of its physical parameters).
        physical: the draws of ``family``'s parameters.
    """

    label: str
    params: Params | None
    from_run: bool
    fold: bool
    constants: HemisphereConstants | None
    scene: str
    family: ModelFamily | None = None
    physical: dict[str, np.ndarray] | None = None

    @property
    def count(self) -> int:
        """Number of parameter sets (posterior draws; 1 for a parameter set)."""
        if self.family is not None:
            return int(np.size(next(iter(self.physical.values()))))
        return int(np.size(self.params.brdf0))


def planned_files(source: Source, export_format: str, draws: int) -> list[str]:
    """Names of the files an export writes (checked against ``--force`` before any work)."""
    if export_format == "abg":
        return ["abg.json", "abg.csv"]
    if not source.from_run:
        return ["params.bsdf"]
    bands = [f"{kind}.bsdf" for kind in _BAND_QUANTILES]
    return bands + [f"draw_{k:03d}.bsdf" for k in range(draws)]


def draw_indices(count: int, draws: int) -> np.ndarray:
    """``draws`` evenly spaced indices into ``count`` posterior draws (deterministic)."""
    return np.unique(np.round(np.linspace(0, count - 1, draws)).astype(int))
