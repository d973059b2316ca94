"""Code size (issue 23): no module over ``MODULE_LIMIT`` lines and no function over
``FUNCTION_LIMIT`` lines without a comment saying why.

Every module under ``brdf_infer/`` is parsed with ``ast`` (nothing is imported). A module's size
is its number of lines; a function's (or method's, nested functions included) is
``end_lineno - lineno + 1`` of its ``def``, docstring included. A function over the limit is
excused by a ``#`` comment line immediately above its ``def`` or its first decorator: the
comment says why splitting it would hurt.

"""

import ast
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = "brdf_infer"
MODULE_LIMIT = 500
FUNCTION_LIMIT = 80


@dataclass(frozen=True)
class LongFunction:
    """A function over ``FUNCTION_LIMIT`` lines."""

    path: str  # relative to the repository
    line: int
    name: str  # qualified: Class.method, outer.inner
    lines: int
    excused: bool  # a comment right above says why it stays whole

    def __str__(self) -> str:
        return f"{self.path}:{self.line}: {self.name} has {self.lines} lines"


def _modules(root: Path) -> list[Path]:
    return sorted((root / PACKAGE).rglob("*.py"))


def module_sizes(root: Path = ROOT) -> dict[str, int]:
    """Every module of the package (path relative to ``root``) → its number of lines."""
    return {
        path.relative_to(root).as_posix(): len(path.read_text(encoding="utf-8").splitlines())
        for path in _modules(root)
    }


def _commented(lines: list[str], node: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    """Whether a ``#`` comment line sits right above the ``def`` or its first decorator."""
    above = {node.lineno - 1, *(d.lineno - 1 for d in node.decorator_list[:1])}
    return any(n >= 1 and lines[n - 1].lstrip().startswith("#") for n in above)


def _functions(node: ast.AST, prefix: str = ""):
    """Every function under ``node`` with its qualified name (``Class.method``,
    ``outer.inner``)."""
    for child in ast.iter_child_nodes(node):
        name = prefix
        if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            name = f"{prefix}{child.name}."
        if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
            yield name[:-1], child
        yield from _functions(child, name)


def long_functions(root: Path = ROOT, limit: int = FUNCTION_LIMIT) -> list[LongFunction]:
    """Every function of the package longer than ``limit`` lines, excused or not."""
    found = []
    for path in _modules(root):
        text = path.read_text(encoding="utf-8")
        lines = text.splitlines()
        for name, node in _functions(ast.parse(text, filename=str(path))):
            length = node.end_lineno - node.lineno + 1
            if length > limit:
                module = path.relative_to(root).as_posix()
                found.append(
                    LongFunction(module, node.lineno, name, length, _commented(lines, node))
                )
    return found


def test_no_module_is_over_the_limit():
    over = {m: n for m, n in module_sizes().items() if n > MODULE_LIMIT}
    assert not over, f"modules over {MODULE_LIMIT} lines: {over}"


def test_long_functions_say_why():
    unexcused = [f for f in long_functions() if not f.excused]
    assert not unexcused, (
        f"functions over {FUNCTION_LIMIT} lines with no comment above saying why:\n"
        + "\n".join(str(f) for f in unexcused)
    )


def test_sizes_are_counted_as_documented(tmp_path):
    """A planted module: its line count, a long function with and without a comment above, a
    long method with one above its decorator, a long one with a comment that is not right
    above it, and one exactly at the limit."""
    body = [f"    x{k} = {k}" for k in range(FUNCTION_LIMIT)]  # with the def: one line too many
    lines = [
        '"""A module."""',
        "def long():",
        *body,
        "# one straight-line template: splitting it would scatter it",
        "def excused():",
        *body,
        "class C:",
        "    # why",
        "    @staticmethod",
        "    def method():",
        *("    " + line for line in body),
        "# a comment, then a blank line",
        "",
        "def detached():",
        *body,
        "def at_the_limit():",
        *body[1:],
    ]
    (tmp_path / PACKAGE).mkdir()
    (tmp_path / PACKAGE / "m.py").write_text("\n".join(lines) + "\n", encoding="utf-8")
    assert module_sizes(tmp_path) == {f"{PACKAGE}/m.py": len(lines)}
    found = {f.name: (f.lines, f.excused) for f in long_functions(tmp_path)}
    assert found == {
        "long": (FUNCTION_LIMIT + 1, False),
        "excused": (FUNCTION_LIMIT + 1, True),
        "C.method": (FUNCTION_LIMIT + 1, True),
        "detached": (FUNCTION_LIMIT + 1, False),
    }
