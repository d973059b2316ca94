"""ArviZ behind one adapter: ``brdf_infer/_internal/arviz.py`` is the only module of the package
that imports ``arviz``, and the others use only the names it defines (so that the port to ArviZ
1.x changes that file alone). Parsed with ``ast``: nothing is imported."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ADAPTER = ROOT / "brdf_infer" / "_internal" / "arviz.py"


def _imported_modules(tree: ast.AST) -> list[tuple[int, str]]:
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            found.append((node.lineno, node.module))
    return found


def _adapter_names() -> set[str]:
    for node in ast.parse(ADAPTER.read_text()).body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
        ):
            return set(ast.literal_eval(node.value))
    raise AssertionError("brdf_infer/_internal/arviz.py has no __all__")


def _adapter_aliases(tree: ast.AST) -> set[str]:
    """The names under which a module binds the adapter (``from brdf_infer._internal import
    arviz as az``)."""
    return {
        alias.asname or alias.name
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom) and node.module == "brdf_infer._internal"
        for alias in node.names
        if alias.name == "arviz"
    }


def test_only_the_adapter_imports_arviz():
    offenders = [
        f"{path.relative_to(ROOT)}:{line}: {module}"
        for path in sorted((ROOT / "brdf_infer").rglob("*.py"))
        if path != ADAPTER
        for line, module in _imported_modules(ast.parse(path.read_text()))
        if module == "arviz" or module.startswith("arviz.")
    ]
    assert offenders == [], "import ArviZ through brdf_infer/_internal/arviz.py"


@pytest.mark.full
@pytest.mark.parametrize("folder", ["brdf_infer", "tests", "tools"])
def test_every_arviz_name_used_is_defined_by_the_adapter(folder):
    names = _adapter_names()
    missing = []
    for path in sorted((ROOT / folder).rglob("*.py")):
        tree = ast.parse(path.read_text())
        aliases = _adapter_aliases(tree)
        missing += [
            f"{path.relative_to(ROOT)}:{node.lineno}: {node.value.id}.{node.attr}"
            for node in ast.walk(tree)
            if isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name)
            and node.value.id in aliases
            and node.attr not in names
            and not node.attr.startswith("__")
        ]
    assert missing == [], "add these to brdf_infer/_internal/arviz.py (and its __all__)"


def test_the_adapter_defines_what_it_lists():
    from brdf_infer._internal import arviz

    assert [name for name in arviz.__all__ if not hasattr(arviz, name)] == []
