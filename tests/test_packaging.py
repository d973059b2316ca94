"""The installed package holds every subpackage of the source tree (a wheel built from
pyproject.toml's explicit package list would otherwise miss one silently)."""

import tomllib
from pathlib import Path

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
