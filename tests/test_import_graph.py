"""The package's import graph: data flow in one direction, private names kept at home.

Every module under ``brdf_infer/`` is parsed with ``ast`` (nothing is imported), and every
``import`` statement in it counts, absolute or relative, at module level, inside a function or
under ``if TYPE_CHECKING:``: an import moved into a function still makes a cycle.
An arrow goes from the importing module to the module it names; ``from x import y`` where
``x.y`` is a module is an arrow to ``x.y``. Importing ``p.q`` from outside package ``p`` runs
``p/__init__.py`` first, so it is also an arrow to ``p`` (the top package ``brdf_infer`` is left
out of that: every module sits inside it).

Rooms. Every entry of the top level (``scene/``, ``model/``, ``errors.py``, ``_internal/``, …)
is a room, and a room imports every room its modules import. The rooms make no cycle either, so
they stand on floors, each above every room it imports: a cycle between two rooms is an arrow
back up even where no module cycle shows it.

Private names. A name is private when it starts with one underscore (dunder names such as
``__version__`` are not private): a module (``posterior._nuts``) or an attribute
(``lsq._residuals``). Where a private name sits is a directory: a private module ``d/_m.py`` (or
a private package ``d/_p/``) sits in ``d``; a private attribute defined in ``d/m.py`` or
``d/__init__.py`` sits in ``d``. The rule (no private names of other packages; this docstring
is where it is written down):

* a private attribute may be imported only by a module in the same directory;
* a private module may be imported by a module of its own package, which for Python includes
  the package's subpackages: ``brdf_infer/_internal/`` (``atomic``, ``outlock``, ``units``, …)
  is the private package of the top package's shared helpers and every module of
  ``brdf_infer`` may use the public names of its modules, while
  ``brdf_infer/posterior/_nuts.py`` is private to ``brdf_infer.posterior`` and the rest of the
  toolkit reaches what it needs through ``brdf_infer.posterior``'s re-exports;
* a private name of another distribution (``jax._src``, ``numpyro.infer._x``) is never
  imported.
"""

import ast
import functools
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = "brdf_infer"


@dataclass(frozen=True)
class Import:
    """One name imported by one module, as written in its source."""

    importer: str  # dotted module name
    line: int
    target: str  # the module the arrow goes to
    names: tuple[str, ...]  # the dotted path as written, module then attribute


def _is_private(part: str) -> bool:
    return part.startswith("_") and not (part.startswith("__") and part.endswith("__"))


def _module_names(root: Path) -> dict[str, Path]:
    """Every module of the package, by dotted name (a package by its ``__init__``)."""
    modules = {}
    for path in sorted((root / PACKAGE).rglob("*.py")):
        parts = path.relative_to(root).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        modules[".".join(parts)] = path
    return modules


def _package_of(module: str, modules: dict[str, Path]) -> str:
    """The package a module sits in (a package's ``__init__`` sits in the package itself)."""
    if modules[module].name == "__init__.py":
        return module
    return module.rpartition(".")[0]


def _resolve(node: ast.ImportFrom, importer: str, modules: dict[str, Path]) -> str:
    if not node.level:
        return node.module or ""
    base = _package_of(importer, modules).split(".")
    base = base[: len(base) - node.level + 1]
    return ".".join(base + ([node.module] if node.module else []))


@functools.cache
def imports_of(root: Path = ROOT) -> tuple[dict[str, Path], list[Import]]:
    """The package's modules and every import written in them."""
    modules = _module_names(root)
    found = []
    for importer, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    found.append(Import(importer, node.lineno, alias.name, (alias.name,)))
            elif isinstance(node, ast.ImportFrom):
                source = _resolve(node, importer, modules)
                for alias in node.names:
                    dotted = f"{source}.{alias.name}"
                    target = dotted if dotted in modules else source
                    found.append(Import(importer, node.lineno, target, (source, alias.name)))
    return modules, found


def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    """Module → the modules of the package it imports (see the module docstring)."""
    modules, found = imports_of(root)
    graph: dict[str, set[str]] = {module: set() for module in modules}
    for imp in found:
        if imp.target not in modules:
            continue  # another distribution
        graph[imp.importer].add(imp.target)
        parts = imp.target.split(".")
        for depth in range(2, len(parts)):
            parent = ".".join(parts[:depth])
            inside = imp.importer == parent or imp.importer.startswith(parent + ".")
            if parent != imp.target and not inside:
                graph[imp.importer].add(parent)
    for module, targets in graph.items():
        targets.discard(module)
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of the graph as its modules in order (first repeated at the end), or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(module: str) -> list[str] | None:
        state[module] = 1
        path.append(module)
        for target in sorted(graph[module]):
            if state.get(target) == 1:
                return [*path[path.index(target) :], target]
            if target not in state and (cycle := visit(target)):
                return cycle
        path.pop()
        state[module] = 2
        return None

    for module in sorted(graph):
        if module not in state and (cycle := visit(module)):
            return cycle
    return None


@dataclass(frozen=True)
class Crossing:
    """An import of a private name from where the rule does not allow it."""

    path: str  # of the importing module, relative to the repository
    line: int
    written: str  # what it imports: "pkg.mod import name" or "pkg.mod"
    why: str

    def __str__(self) -> str:
        return f"{self.path}:{self.line}: {self.written} ({self.why})"


def private_crossings(root: Path = ROOT) -> list[Crossing]:
    """Every import of a private name from where the rule (module docstring) does not allow it."""
    modules, found = imports_of(root)
    crossings = []
    for imp in found:
        path = modules[imp.importer].relative_to(root).as_posix()
        written = " import ".join(imp.names)
        parts = ".".join(imp.names).split(".")
        if parts[0] != PACKAGE:
            if any(_is_private(part) for part in parts):
                crossings.append(Crossing(path, imp.line, written, "private, another distribution"))
            continue
        importer_dir = _package_of(imp.importer, modules)
        for depth in range(1, len(parts)):
            if not _is_private(parts[depth]):
                continue
            owner = ".".join(parts[:depth])
            if ".".join(parts[: depth + 1]) in modules:  # a private module of package `owner`
                allowed = importer_dir == owner or importer_dir.startswith(owner + ".")
                why = f"private module of {owner}"
            else:  # a private name in module `owner`: private to the directory it sits in
                home = _package_of(owner, modules) if owner in modules else owner
                allowed = importer_dir == home
                why = f"private name of {owner}"
            if not allowed:
                crossings.append(Crossing(path, imp.line, written, why))
                break
    return crossings


def test_the_package_imports_without_a_cycle():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import cycle: " + " → ".join(cycle)


def room_graph(root: Path = ROOT) -> dict[str, set[str]]:
    """The top level's entries (``scene``, ``model``, ``_internal``, …; a room each) → the rooms
    its modules import: the module graph with every module inside its room."""
    rooms: dict[str, set[str]] = {}
    for module, targets in import_graph(root).items():
        room = module.split(".")[1] if "." in module else None
        if room is None:
            continue  # the package's own __init__ re-exports: it sits above every room
        rooms.setdefault(room, set())
        rooms[room] |= {t.split(".")[1] for t in targets if "." in t} - {room}
    return rooms


def test_the_top_level_rooms_import_without_a_cycle():
    """Rooms on floors: no room imports a room that imports it back, even where the modules
    themselves make no cycle (a back-arrow between two packages)."""
    cycle = find_cycle(room_graph())
    assert cycle is None, "rooms importing each other: " + " → ".join(cycle)


def test_the_top_level_holds_few_public_entries():
    """A newcomer reads the top level as the table of contents: at most 16 public packages and
    modules (15 packages and ``errors.py``); the private helpers are in ``_internal/``."""
    public = sorted(
        path.name
        for path in (ROOT / PACKAGE).iterdir()
        if not path.name.startswith("_")
        and (path.suffix == ".py" or (path / "__init__.py").is_file())
    )
    assert len(public) <= 16, f"{len(public)} public top-level entries: {public}"


def test_a_planted_back_arrow_between_rooms_is_found(tmp_path):
    # the run folder (low: the tables' screening writes its records) naming a table module that
    # imports nothing of it: no module cycle, but the rooms `runs` and `tables` import each other
    copy = _planted(
        tmp_path, "brdf_infer.runs.folder", "\nfrom brdf_infer.tables import selections\n"
    )
    assert find_cycle(import_graph(copy)) is None
    assert {"runs", "tables"} <= set(find_cycle(room_graph(copy)) or [])


def test_no_private_name_is_imported_from_another_package():
    crossings = private_crossings()
    assert not crossings, "private names imported across packages:\n" + "\n".join(
        str(c) for c in crossings
    )


def _planted(tmp_path: Path, module: str, source: str) -> Path:
    """A copy of the package with `source` appended to `module` (a dotted name)."""
    copy = tmp_path / "copy"
    for path in (ROOT / PACKAGE).rglob("*.py"):
        target = copy / path.relative_to(ROOT)
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(path.read_text(encoding="utf-8"), encoding="utf-8")
    planted = _module_names(copy)[module]
    planted.write_text(planted.read_text(encoding="utf-8") + source, encoding="utf-8")
    return copy


@pytest.mark.full
@pytest.mark.parametrize(
    ("module", "source"),
    [
        # a back-import at module level, up the data flow
        ("brdf_infer.tables.measurements", "\nfrom brdf_infer import report\n"),
        # a function-level one, relative, naming a submodule through `from . import`
        ("brdf_infer.posterior._bands", "\ndef f():\n    from ..studies import sbc\n"),
    ],
)
def test_a_planted_back_import_is_found(tmp_path, module, source):
    assert find_cycle(import_graph(ROOT)) is None
    cycle = find_cycle(import_graph(_planted(tmp_path, module, source)))
    assert cycle is not None and module in cycle


@pytest.mark.full
@pytest.mark.parametrize(
    ("module", "source", "found"),
    [
        # a private module of another package, by its dotted name
        (
            "brdf_infer.workflow.batch",
            "\nfrom brdf_infer.posterior._nuts import x\n",
            "posterior._nuts",
        ),
        # a private name of a module in another directory
        ("brdf_infer.studies.compare", "\nfrom brdf_infer.fit.lsq import _x\n", "lsq import _x"),
        # a private module named through `from package import`, relative, in a function
        ("brdf_infer.report._build", "\ndef f():\n    from ..posterior import _bands\n", "_bands"),
        # a private name of a shared helper of the top package, from a subpackage
        (
            "brdf_infer.posterior._run",
            "\nfrom brdf_infer._internal.units import _x\n",
            "units import _x",
        ),
        # a private module of another distribution
        ("brdf_infer.studies.synthetic", "\nimport jax._src.core\n", "jax._src"),
    ],
)
def test_a_planted_private_import_is_found(tmp_path, module, source, found):
    assert not [c for c in private_crossings(ROOT) if found in c.written]
    crossings = private_crossings(_planted(tmp_path, module, source))
    assert any(found in c.written for c in crossings), crossings


@pytest.mark.full
@pytest.mark.parametrize(
    ("module", "source"),
    [
        ("brdf_infer.posterior._run", "\nfrom ._nuts import stack_data\n"),  # same package
        (
            "brdf_infer.posterior._run",
            "\nfrom brdf_infer._internal.atomic import atomic_write_json\n",
        ),
        ("brdf_infer.report._sbc", "\nfrom brdf_infer._internal import outlock\n"),  # a helper
        ("brdf_infer.fit.paper", "\nfrom brdf_infer.fit.lsq import _x\n"),  # the same directory
        ("brdf_infer.report", "\nfrom brdf_infer.report._html import page\n"),  # its __init__
    ],
)
def test_private_names_may_be_used_at_home(tmp_path, module, source):
    assert private_crossings(_planted(tmp_path, module, source)) == private_crossings(ROOT)
