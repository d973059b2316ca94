"""The installed package holds every subpackage of the source tree (a wheel built from
pyproject.toml's explicit package list would otherwise miss one silently)."""

import os
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_every_subpackage_is_installed():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    listed = set(config["tool"]["setuptools"]["packages"])
    on_disk = {
        ".".join(init.parent.relative_to(ROOT).parts)
        for init in (ROOT / "brdf_infer").rglob("__init__.py")
    }
    assert on_disk - listed == set(), "add these to [tool.setuptools] packages"


def _requirements(config: dict, extras: tuple[str, ...]) -> list:
    """The project's dependencies and those of ``extras``, its own extras
    (``brdf_infer[docs]``) expanded."""
    from packaging.requirements import Requirement

    optional = config["project"]["optional-dependencies"]
    pending = [Requirement(text) for text in config["project"]["dependencies"]]
    pending += [Requirement(text) for extra in extras for text in optional[extra]]
    found, seen = [], set(extras)
    while pending:
        requirement = pending.pop()
        if requirement.name == config["project"]["name"]:
            pending += [Requirement(t) for e in requirement.extras - seen for t in optional[e]]
            seen |= requirement.extras
        else:
            found.append(requirement)
    return found


def test_constraints_pin_every_dependency_within_its_bounds():
    """``./dev`` installs with ``-c constraints.txt``: every package the package and its test
    extra name is pinned there, to a version pyproject.toml allows (an unpinned one would
    install the newest release whenever the environment is set up)."""
    from packaging.utils import canonicalize_name

    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    pins = {}
    for line in (ROOT / "constraints.txt").read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            name, _, version = line.partition("==")
            pins[canonicalize_name(name)] = version.strip()
    requirements = _requirements(config, ("test",))
    assert {"mkdocs", "pytest", "jax", "arviz"} <= {r.name for r in requirements}
    unpinned = [str(r) for r in requirements if canonicalize_name(r.name) not in pins]
    assert unpinned == [], "refresh constraints.txt: tools/freeze_constraints.py"
    outside = [
        f"{r} (pinned {pins[canonicalize_name(r.name)]})"
        for r in requirements
        if not r.specifier.contains(pins[canonicalize_name(r.name)], prereleases=True)
    ]
    assert outside == []


def test_dev_installs_with_the_constraints_and_reinstalls_when_they_change():
    script = (ROOT / "dev").read_text()
    assert "pip install --quiet -c constraints.txt -e" in script
    assert "cat pyproject.toml constraints.txt | sha256sum" in script


# what the installed package must never import: the test and peers extras, the benchmarks
NOT_IN_THE_PACKAGE = {"hypothesis", "pytest", "pymc", "nutpie", "benchmarks", "tests"}


def test_no_module_of_the_package_imports_a_test_or_peers_extra():
    """No module under ``brdf_infer/`` imports ``hypothesis``, ``pytest``, ``pymc``,
    ``nutpie``, the benchmarks or the tests (at module level or in a function): a wheel
    installs and runs with the core dependencies alone. The benchmarks live in the checkout's
    ``benchmarks/``, outside what is installed."""
    import ast

    found = []
    for path in sorted((ROOT / "brdf_infer").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            found += [
                f"{path.relative_to(ROOT)}:{node.lineno} {name}"
                for name in names
                if name.split(".")[0] in NOT_IN_THE_PACKAGE
            ]
    assert found == []
    assert not (ROOT / "brdf_infer" / "bench").exists()


BLOCKER = """
import sys
BLOCKED = {blocked!r}
class Blocker:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"{{name}} is not installed here (blocked)")
        return None
sys.meta_path.insert(0, Blocker())
"""


@pytest.mark.slow  # ≈ 1 minute: builds the wheel, installs it, runs the main job
def test_a_wheel_runs_every_command_with_the_core_dependencies_alone(tmp_path):
    """A wheel built from the checkout (pip fetches the build backend, setuptools ≥ 77) holds
    ``brdf_infer`` and its data and nothing else; in
    a fresh virtual environment that sees the core dependencies (this environment's packages,
    with the test and peers extras made unimportable) and not the checkout, ``brdf-infer run
    lya`` completes and every command's ``--help`` works; ``brdf-infer bench`` says in one
    line that the benchmarks live in a checkout."""
    import site
    import zipfile

    source = tmp_path / "source"  # setuptools builds in the source tree: not the checkout's
    shutil.copytree(
        ROOT,
        source,
        ignore=shutil.ignore_patterns(
            ".git", ".venv", "build", "*.egg-info", "reports", ".*cache", ".hypothesis"
        ),
    )
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-w", str(tmp_path / "wheel"),
         str(source)],
        check=True, capture_output=True, timeout=600,
    )  # fmt: skip
    (wheel,) = (tmp_path / "wheel").glob("brdf_infer-*.whl")
    tops = {name.split("/")[0] for name in zipfile.ZipFile(wheel).namelist()}
    assert {t for t in tops if not t.endswith(".dist-info")} == {"brdf_infer"}, tops
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    python = venv / "bin" / "python"
    subprocess.run(
        [str(python), "-m", "pip", "install", "--no-deps", "--no-index", str(wheel)],
        check=True, capture_output=True, timeout=600,
    )  # fmt: skip
    lib = next((venv / "lib").glob("python3*/site-packages"))
    (lib / "core_dependencies.pth").write_text(
        "\n".join(p for p in site.getsitepackages() if "site-packages" in p) + "\n"
    )
    (lib / "block_extras.py").write_text(BLOCKER.format(blocked=sorted(NOT_IN_THE_PACKAGE)))
    (lib / "block_extras.pth").write_text("import block_extras\n")
    environment = {**os.environ, "BRDF_INFER_CACHE": str(tmp_path / "cache")}
    environment.pop("PYTHONPATH", None)

    def command(*argv: str) -> subprocess.CompletedProcess:
        return subprocess.run(
            [str(venv / "bin" / "brdf-infer"), *argv],
            capture_output=True, text=True, cwd=tmp_path, env=environment, timeout=900,
        )  # fmt: skip

    where = subprocess.run(
        [str(python), "-c", "import brdf_infer; print(brdf_infer.__file__)"],
        capture_output=True, text=True, cwd=tmp_path, env=environment, check=True,
    ).stdout  # fmt: skip
    assert str(lib) in where, where
    names = re.findall(r"^    (\w[\w-]*)\s", command("--help").stdout, re.MULTILINE)
    assert "run" in names and "report" in names, names
    for name in names:
        result = command(name, "--help")
        assert result.returncode == 0, (name, result.stderr)
    result = command("run", "lya", "--out", str(tmp_path / "lya"))
    assert result.returncode == 0, result.stderr[-2000:]
    assert (tmp_path / "lya" / "report.html").is_file()
    result = command("bench", "--quick")
    assert result.returncode == 2 and "checkout" in result.stderr, result.stderr
