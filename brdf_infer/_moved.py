"""The old import paths of the modules that moved into the grouped packages (``fit/``,
``studies/``, ``tables/``, ``model/``, ``runs/``, ``predict/``, ``verdict/``, ``workflow/``,
``report/``, ``scene/``).

For one release each old path still imports (``import brdf_infer.lsq``,
``from brdf_infer.lsq import fit_lsq``, ``from brdf_infer import lsq``) and gives the same
module object as the new path, so monkeypatching and ``isinstance`` keep working; the first
import of an old path in a process warns with :class:`FutureWarning` naming the new one.
:data:`MOVED` is the table; :func:`install` puts the finder on ``sys.meta_path`` (the package's
``__init__`` calls it) and ``brdf_infer.__getattr__`` serves ``from brdf_infer import lsq``.
"""

import importlib
import importlib.abc
import importlib.machinery
import sys
import types
import warnings

# old dotted name → new dotted name; the old names go in the next release
MOVED: dict[str, str] = {
    "brdf_infer.lsq": "brdf_infer.fit.lsq",
    "brdf_infer.fit_quality": "brdf_infer.fit.quality",
    "brdf_infer.paper_fit": "brdf_infer.fit.paper",
    "brdf_infer.sensitivity": "brdf_infer.studies.sensitivity",
    "brdf_infer.compare": "brdf_infer.studies.compare",
    "brdf_infer.sbc": "brdf_infer.studies.sbc",
    "brdf_infer.instrument_bias": "brdf_infer.studies.instrument_bias",
    "brdf_infer.instrument_comparison": "brdf_infer.studies.instrument_comparison",
    "brdf_infer.synthetic": "brdf_infer.studies.synthetic",
    "brdf_infer.uniformity": "brdf_infer.studies.uniformity",
    "brdf_infer.measurements": "brdf_infer.tables.measurements",
    "brdf_infer.bsdf_file": "brdf_infer.tables.bsdf_file",
    "brdf_infer.bsdf_measurements": "brdf_infer.tables.bsdf_measurements",
    "brdf_infer.table_screening": "brdf_infer.tables.screening",
    "brdf_infer.selections": "brdf_infer.tables.selections",
    "brdf_infer.params": "brdf_infer.model.params",
    "brdf_infer.priors": "brdf_infer.model.priors",
    "brdf_infer.coordinates": "brdf_infer.model.coordinates",
    "brdf_infer.error_model": "brdf_infer.model.error_model",
    "brdf_infer.run_folder": "brdf_infer.runs.folder",
    "brdf_infer.run_records": "brdf_infer.runs.records",
    "brdf_infer.observations": "brdf_infer.predict.observations",
    "brdf_infer.plausibility": "brdf_infer.verdict.plausibility",
    "brdf_infer.batch": "brdf_infer.workflow.batch",
    "brdf_infer.export": "brdf_infer.report.export",
    "brdf_infer.raytrace": "brdf_infer.studies.raytrace",
    "brdf_infer.settings": "brdf_infer.scene.settings",
}

# the frames a warning skips to reach the importing line: the import system, this module, and
# the package's __init__ (its __getattr__)
_INTERNAL = (
    "<frozen importlib",
    importlib.__file__,
    __file__,
    __file__.replace("_moved", "__init__"),
)


def _warn(old: str, new: str) -> None:
    """FutureWarning at the first frame outside the import machinery (the caller's line)."""
    frame, level = sys._getframe(0), 1
    while frame is not None and frame.f_code.co_filename.startswith(_INTERNAL):
        frame = frame.f_back
        name = frame.f_code.co_filename if frame is not None else ""
        level += not ("importlib" in name and "_bootstrap" in name)  # warn() skips those itself
    message = f"{old} moved to {new}; the old path goes in the next release"
    warnings.warn(message, FutureWarning, stacklevel=level)


class _Loader(importlib.abc.Loader):
    """Gives the new module for the old name (no second copy of it)."""

    def __init__(self, new: str) -> None:
        self.new = new

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> types.ModuleType:
        try:
            module = importlib.import_module(self.new)
        except ImportError as err:
            raise ModuleNotFoundError(
                f"{spec.name} moved to {self.new}, which does not import: {err}", name=spec.name
            ) from err
        _warn(spec.name, self.new)
        self.spec = module.__spec__  # the import system sets the old spec; exec_module puts it back
        return module

    def exec_module(self, module: types.ModuleType) -> None:
        module.__spec__ = self.spec


def new_name(old: str) -> str | None:
    """The new dotted name of an old one: a moved module, or a module inside a moved package
    (``brdf_infer.batch._team`` → ``brdf_infer.workflow.batch._team``, which would otherwise
    load a second copy of the file under the old name); None for a name that did not move."""
    if old in MOVED:
        return MOVED[old]
    package = next((name for name in MOVED if old.startswith(name + ".")), None)
    return None if package is None else MOVED[package] + old[len(package) :]


class _Finder(importlib.abc.MetaPathFinder):
    """Finds the old names of :data:`MOVED` and of the modules inside them, nothing else."""

    def find_spec(self, fullname, path=None, target=None):
        new = new_name(fullname)
        if new is None:
            return None
        return importlib.machinery.ModuleSpec(fullname, _Loader(new))


def install() -> None:
    """Put the finder first on ``sys.meta_path`` (once)."""
    if not any(isinstance(finder, _Finder) for finder in sys.meta_path):
        sys.meta_path.insert(0, _Finder())


def attribute(package: str, name: str) -> types.ModuleType:
    """``from <package> import <name>`` for an old module name, or AttributeError."""
    old = f"{package}.{name}"
    if old not in MOVED:
        raise AttributeError(f"module {package!r} has no attribute {name!r}")
    return importlib.import_module(old)
