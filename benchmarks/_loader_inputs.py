"""Generated inputs for every loader (Hypothesis strategies) and the check each must pass.

Every loader of user files — the measurement CSV (both quantities, ``phi_s_deg``), the scene
TOML (every table and key), a Zemax tabular ``.BSDF`` file and a parameter JSON file or inline
object — must end each input in a result or in one :class:`~brdf_infer.errors.BadInputError`
(one line naming the file or option, exit 2 on the command line): never another exception,
never a file written. A result must hold what the loader promises (finite angles in range,
positive values, no duplicate rows, …).

The strategies start from well-formed files and break them the ways files from other tools
and hands are broken: delimiters, encodings and byte-order marks, line endings, quoting,
huge, tiny and non-finite numbers, duplicated rows and columns, wrong types and unknown keys,
missing and odd paths, header lines out of order, counts that disagree with the data, tabs,
truncation. ``tests/test_loader_inputs.py`` runs them in the suite (a fast profile) and in the
``slow`` set (5,000 inputs per loader); :func:`benchmarks._robustness.loader_rows`
counts them for the benchmark. Needs Hypothesis (the ``test`` extra).

The inputs of each loader are in its own module: ``_inputs_csv``, ``_inputs_scene``,
``_inputs_bsdf`` and ``_inputs_params`` (what they are made of in ``_inputs``); this module
names the loaders and runs one on an input.
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hypothesis import strategies as st

from benchmarks._inputs_bsdf import _bsdf_command, _read_bsdf, _write_bsdf, bsdf_files
from benchmarks._inputs_csv import (
    _csv_command,
    _read_csv,
    _write_csv,
    check_measurements,
    measurement_csvs,
)
from benchmarks._inputs_params import (
    _params_command,
    _read_params,
    _write_params,
    check_params,
    parameter_inputs,
)
from benchmarks._inputs_scene import _read_scene, _write_scene, check_scene, scene_files
from brdf_infer.errors import BadInputError


@dataclass(frozen=True)
class Loader:
    """A loader under test: its inputs, how to put one in a folder (the path or argument the
    loader is given), how to read it, what its result promises."""

    name: str
    inputs: Callable[[], st.SearchStrategy[Any]]
    prepare: Callable[[Path, Any], Any]
    read: Callable[[Any, Any], Any]
    check: Callable[[Any], None]
    command: Callable[[Any, Any], list[str] | None]  # brdf-infer arguments that read it


LOADERS: dict[str, Loader] = {
    loader.name: loader
    for loader in (
        Loader(
            "measurement CSV",
            measurement_csvs,
            _write_csv,
            _read_csv,
            lambda rows: check_measurements(rows, {"I", "II"}),
            _csv_command,
        ),
        Loader(
            "scene TOML",
            scene_files,
            _write_scene,
            _read_scene,
            check_scene,
            lambda path, given: ["fit", str(path), "--method", "paper"],
        ),
        Loader(
            "Zemax .BSDF", bsdf_files, _write_bsdf, _read_bsdf, check_measurements, _bsdf_command
        ),
        Loader(
            "parameter JSON",
            parameter_inputs,
            _write_params,
            _read_params,
            check_params,
            _params_command,
        ),
    )
}


def _listing(folder: Path) -> dict[str, int]:
    return {str(p.relative_to(folder)): p.stat().st_size for p in folder.rglob("*")}


def run_loader(
    loader: Loader, given: Any, refused: Callable[[list[str], str], None] | None = None
) -> BadInputError | None:
    """Load ``given`` in a fresh folder: None for a result that holds what the loader
    promises, the error for a refusal (one line, naming a file or an option). ``refused``
    is called with the loader's command line and the refusal's message (in the folder, before
    it goes).

    Raises:
        AssertionError: a result that breaks its promises, a message of several lines, a
            refusal naming neither file nor option, or a file written or removed.
        Exception: any error other than BadInputError (a traceback on the command line).
    """
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        target = loader.prepare(folder, given)
        before = _listing(folder)
        try:
            result = loader.read(target, given)
        except BadInputError as error:
            message = str(error)
            assert message and "\n" not in message and "\r" not in message, repr(message)
            assert error.file is not None or error.field is not None, message
            assert _listing(folder) == before, "the loader wrote a file"
            argv = loader.command(target, given)
            if refused is not None and argv is not None:
                refused(argv, message)
            return error
        assert _listing(folder) == before, "the loader wrote a file"
        loader.check(result)
        return None
