"""What an export is made from (:class:`Source`: one parameter set or a posterior run) and the
files it writes (the module docstring of :mod:`._files` says what each means)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from brdf_infer.model import ModelFamily
from brdf_infer.model.params import PARAM_NAMES, HemisphereConstants, Params

_BAND_QUANTILES = {"lower95": 0.025, "median": 0.5, "upper95": 0.975}
# the posterior draw at each TIS quantile: a real BRDF, the envelope file of the same quantile
_TIS_QUANTILE_FILES = {"tis_q025": "lower95", "tis_q500": "median", "tis_q975": "upper95"}


@dataclass(frozen=True)
class Source:
    """Where the exported BRDF comes from: one parameter set or every draw of a posterior run,
    of any model family.

    Attributes:
        label: the parameter set's name or the run folder, for the file comments.
        family: the model family; its ``fold`` (Eq. 10 in the BRDF: the article's Table 3 has
            it; False: the physical BRDF) and ``constants`` (Δφ, folding) are the export's.
        physical: the family's physical parameters: scalars (one parameter set) or 1-D arrays
            (every posterior draw).
        from_run: ``physical`` holds posterior draws.
        scene: the scene's name, for the file comments.
        target: which coating a run's draws describe (``measured``, ``sample NAME``,
            ``coating`` or ``new_part``; :mod:`brdf_infer.posterior._targets`); empty for a
            parameter set.
    """

    label: str
    family: ModelFamily
    physical: dict[str, np.ndarray]
    from_run: bool
    scene: str
    target: str = ""

    @property
    def fold(self) -> bool:
        return self.family.fold

    @property
    def constants(self) -> HemisphereConstants:
        return self.family.constants

    @property
    def params(self) -> Params:
        """The physical parameters as Eq. (7)'s six (its family only).

        Raises:
            ValueError: a source of another family.
        """
        if not self.family.paper_parameters:
            raise ValueError(f"{self.family.name} has no Eq. (7) parameters")
        return Params(*(np.asarray(self.physical[name], float) for name in PARAM_NAMES))

    @property
    def count(self) -> int:
        """Number of parameter sets (posterior draws; 1 for a parameter set)."""
        return int(np.size(next(iter(self.physical.values()))))


def planned_files(source: Source, export_format: str, draws: int) -> list[str]:
    """Names of the files an export writes (checked against ``--force`` before any work)."""
    if export_format == "abg":
        return ["abg.json", "abg.csv"]
    if not source.from_run:
        return ["params.bsdf"]
    bands = [f"{kind}.bsdf" for kind in (*_BAND_QUANTILES, *_TIS_QUANTILE_FILES)]
    return bands + [f"draw_{k:03d}.bsdf" for k in range(draws)]


def draw_indices(count: int, draws: int) -> np.ndarray:
    """``draws`` evenly spaced indices into ``count`` posterior draws (deterministic)."""
    return np.unique(np.round(np.linspace(0, count - 1, draws)).astype(int))
