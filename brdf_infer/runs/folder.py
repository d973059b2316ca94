"""The run folder, one owner: its file names, its atomic writers and its typed readers.

A run folder (``brdf-infer run --out DIR``, ``posterior --out DIR``) holds the posterior and
what the studies and commands add beside it. Every module that writes or reads one of its files
goes through :class:`RunFolder`, so the folder's layout is written down once, here::

    posterior.nc            the posterior (ArviZ InferenceData, netCDF)
    summary.json            what ran, the answer, how far to trust it (PosteriorSummary)
    bands.json              the BRDF and TIS bands (Bands)
    emcee_checkpoint.npz    an interrupted emcee run's state (removed when it completes)
    fit_lsq.json            the least-squares fit (``run``)
    fit_paper.json          the article's linear regression (``run``, Eq. 7 scenes)
    studies.json            the studies ``run`` ran and left out
    compare.json, .png      the model comparison (PSIS-LOO)
    sensitivity.json, .png  the error-model sensitivity study
    design.json, .png       where to measure next
    instruments.json        the posteriors under other instrument models
    raytrace.json           the ray traces (Sec. 6)
    detector_images.npz     the simulated detector images (Fig. 13)
    exports.json            the exports made from the run, for the report
    report.html, figures/   the report
    variants/NAME/          a study's posterior (a run folder of its own)
    .brdf-infer.lock        a writer at work, or one that stopped before finishing
                            (brdf_infer._internal.outlock)

A study folder of its own (``sbc --out``, ``batch --out``) uses the same writers with
``sbc.json`` and ``batch.json``. Readers of old run folders keep working: a study's file that
is absent reads as None (or an empty list), never as an error. Units inside the files:
:mod:`brdf_infer.runs.records`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from brdf_infer._internal.atomic import atomic_write_bytes, atomic_write_json
from brdf_infer._internal.outlock import ADDING_LOCK_FILE, LOCK_FILE
from brdf_infer.errors import BadInputError
from brdf_infer.runs.records import Bands, PosteriorSummary

POSTERIOR_FILE = "posterior.nc"
SUMMARY_FILE = "summary.json"
BANDS_FILE = "bands.json"
CHECKPOINT_FILE = "emcee_checkpoint.npz"
FIT_LSQ_FILE = "fit_lsq.json"
FIT_PAPER_FILE = "fit_paper.json"
STUDIES_FILE = "studies.json"
COMPARE_FILE = "compare.json"
COMPARE_FIGURE = "compare.png"
SENSITIVITY_FILE = "sensitivity.json"
SENSITIVITY_FIGURE = "sensitivity.png"
DESIGN_FILE = "design.json"
DESIGN_FIGURE = "design.png"
INSTRUMENT_FILE = "instruments.json"
RAYTRACE_FILE = "raytrace.json"
DETECTOR_IMAGES_FILE = "detector_images.npz"
EXPORTS_FILE = "exports.json"
REPORT_FILE = "report.html"
FIGURE_DIR = "figures"
VARIANTS_DIR = "variants"
SBC_FILE = "sbc.json"
BATCH_FILE = "batch.json"

__all__ = [
    "ADDING_LOCK_FILE",
    "BANDS_FILE",
    "BATCH_FILE",
    "CHECKPOINT_FILE",
    "COMPARE_FIGURE",
    "COMPARE_FILE",
    "DESIGN_FIGURE",
    "DESIGN_FILE",
    "DETECTOR_IMAGES_FILE",
    "EXPORTS_FILE",
    "FIGURE_DIR",
    "FIT_LSQ_FILE",
    "FIT_PAPER_FILE",
    "INSTRUMENT_FILE",
    "LOCK_FILE",
    "POSTERIOR_FILE",
    "RAYTRACE_FILE",
    "REPORT_FILE",
    "SBC_FILE",
    "SENSITIVITY_FIGURE",
    "SENSITIVITY_FILE",
    "STUDIES_FILE",
    "SUMMARY_FILE",
    "VARIANTS_DIR",
    "RunFolder",
    "read_json_file",
]


def read_json_file(path: str | Path, *, encoding: str = "utf-8") -> Any:
    """The JSON content of ``path`` (any JSON file: a run folder's, a user's parameter file).

    Raises:
        BadInputError: ``path`` cannot be read or holds no valid JSON (naming the file and,
            for a syntax error, its line).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding=encoding)
    except FileNotFoundError:
        raise BadInputError("no such file", file=path) from None
    except (OSError, UnicodeDecodeError) as error:
        raise BadInputError(f"cannot read: {error}", file=path) from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as error:
        raise BadInputError(f"not valid JSON: {error.msg}", file=path, line=error.lineno) from None
    except RecursionError:
        raise BadInputError("not valid JSON: nested too deeply", file=path) from None


@dataclass(frozen=True)
class RunFolder:
    """A run folder at ``path`` (it need not exist yet: the writers create it).

    Attributes:
        path: the folder.
    """

    path: Path

    def __post_init__(self) -> None:
        object.__setattr__(self, "path", Path(self.path))

    def file(self, name: str) -> Path:
        """The path of the folder's file ``name`` (one of this module's ``*_FILE`` names)."""
        return self.path / name

    def has(self, name: str) -> bool:
        """Whether the folder holds the file ``name``."""
        return self.file(name).is_file()

    def variant(self, name: str) -> RunFolder:
        """The run folder of the study's posterior ``variants/NAME``."""
        return RunFolder(self.path / VARIANTS_DIR / name)

    @property
    def posterior_file(self) -> Path:
        """``posterior.nc``."""
        return self.file(POSTERIOR_FILE)

    @property
    def checkpoint_file(self) -> Path:
        """``emcee_checkpoint.npz``."""
        return self.file(CHECKPOINT_FILE)

    @property
    def report_file(self) -> Path:
        """``report.html``."""
        return self.file(REPORT_FILE)

    @property
    def figure_dir(self) -> Path:
        """``figures/``, the report's figures."""
        return self.path / FIGURE_DIR

    # readers

    def read_json(self, name: str, *, optional: bool = False) -> Any:
        """The JSON content of the file ``name`` (``optional``: None when it is absent).

        Raises:
            BadInputError: the file is absent (not ``optional``), unreadable or no JSON.
        """
        if not self.has(name):
            if optional:
                return None
            raise BadInputError(
                f"no {name} here (run 'brdf-infer posterior --out DIR' first)", file=self.path
            )
        return read_json_file(self.file(name))

    def summary(self) -> PosteriorSummary:
        """``summary.json``.

        Raises:
            BadInputError: absent, unreadable or no JSON object.
        """
        return self._record(SUMMARY_FILE)

    def bands(self) -> Bands:
        """``bands.json``.

        Raises:
            BadInputError: absent, unreadable or no JSON object.
        """
        return self._record(BANDS_FILE)

    def posterior_draws(self, name: str) -> np.ndarray:
        """Every draw of the posterior variable ``name`` (chains and draws flattened), read
        from ``posterior.nc`` without the rest of the run.

        Raises:
            BadInputError: no readable posterior.nc, or none with ``name``.
        """
        import xarray

        path = self.posterior_file
        if not path.is_file():
            raise BadInputError(
                "no posterior.nc here (run 'brdf-infer posterior' first)", file=self.path
            )
        try:
            with xarray.open_dataset(path, group="posterior") as posterior:
                if name not in posterior:
                    raise BadInputError(f"its posterior has no {name}", file=path)
                return np.asarray(posterior[name]).reshape(-1)
        except (OSError, ValueError) as error:
            raise BadInputError(f"cannot read: {error}", file=path) from None

    def _record(self, name: str) -> Any:
        content = self.read_json(name)
        if not isinstance(content, dict):
            raise BadInputError("not a JSON object", file=self.file(name))
        return content

    def studies(self) -> dict[str, list[str]] | None:
        """``studies.json``: ``run`` (the studies run) and ``not_run`` (in words); None in a
        ``posterior`` folder."""
        return self.read_json(STUDIES_FILE, optional=True)

    def compare(self) -> dict[str, Any] | None:
        """``compare.json`` (:meth:`brdf_infer.studies.compare.ComparisonResult.as_json`), or
        None."""
        return self.read_json(COMPARE_FILE, optional=True)

    def sensitivity(self) -> dict[str, Any] | None:
        """``sensitivity.json``
        (:meth:`brdf_infer.studies.sensitivity.SensitivityResult.as_json`), or None."""
        return self.read_json(SENSITIVITY_FILE, optional=True)

    def design(self) -> dict[str, Any] | None:
        """``design.json`` (:meth:`brdf_infer.design.DesignResult.as_json`), or None."""
        return self.read_json(DESIGN_FILE, optional=True)

    def instruments(self) -> dict[str, Any] | None:
        """``instruments.json``
        (:func:`brdf_infer.studies.instrument_comparison.compare_instruments`), or None."""
        return self.read_json(INSTRUMENT_FILE, optional=True)

    def traces(self) -> list[dict[str, Any]]:
        """The ray traces of ``raytrace.json``, possibly none.

        Raises:
            BadInputError: the file is there but unreadable, or holds no ``traces``.
        """
        content = self.read_json(RAYTRACE_FILE, optional=True)
        if content is None:
            return []
        if not isinstance(content, dict) or "traces" not in content:
            raise BadInputError(
                "cannot read the ray traces: no 'traces'", file=self.file(RAYTRACE_FILE)
            )
        return content["traces"]

    def exports(self) -> list[dict[str, Any]]:
        """The exports recorded in ``exports.json`` (none where it is absent or unreadable: the
        record is a convenience of the report, rebuilt by the next export)."""
        try:
            entries = self.read_json(EXPORTS_FILE, optional=True) or {"exports": []}
            return list(entries["exports"])
        except (BadInputError, KeyError, TypeError):
            return []

    # writers: atomic (brdf_infer._internal.atomic), the folder created where it is missing

    def write_json(self, name: str, content: Any) -> Path:
        """Write ``content`` as the folder's JSON file ``name``; returns its path.

        Raises:
            OSError: the write failed (naming the file; a file already there is unchanged).
        """
        return atomic_write_json(self.file(name), content)

    def write_bytes(self, name: str, data: bytes) -> Path:
        """Write ``data`` as the folder's file ``name`` (a figure, a netCDF); returns its path.

        Raises:
            OSError: the write failed (naming the file; a file already there is unchanged).
        """
        return atomic_write_bytes(self.file(name), data)

    def write_summary(self, summary: PosteriorSummary) -> Path:
        """Write ``summary.json``."""
        return self.write_json(SUMMARY_FILE, summary)

    def write_bands(self, bands: Bands) -> Path:
        """Write ``bands.json``."""
        return self.write_json(BANDS_FILE, bands)

    def write_studies(self, run: list[str], not_run: list[str]) -> Path:
        """Write ``studies.json``: the studies run and those left out (in words)."""
        return self.write_json(STUDIES_FILE, {"run": run, "not_run": not_run})

    def write_traces(self, traces: list[dict[str, Any]]) -> Path:
        """Write ``raytrace.json``."""
        return self.write_json(RAYTRACE_FILE, {"traces": traces})

    def write_exports(self, entries: list[dict[str, Any]]) -> Path:
        """Write ``exports.json``."""
        return self.write_json(EXPORTS_FILE, {"exports": entries})
