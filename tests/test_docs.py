"""The documentation: the site in docs/ builds with ``mkdocs build --strict`` (a broken link or
anchor, or an API page naming a module that is gone, fails), and README.md stays a front page."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"


@pytest.mark.full
def test_the_site_builds_strictly(tmp_path):
    """mkdocs.yml sets ``strict: true``; ``--strict`` says so again should the file lose it."""
    built = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert built.returncode == 0, built.stderr[-4000:]
    # the API reference was generated from the docstrings, not left as a bare directive
    api = (tmp_path / "site" / "api" / "model" / "index.html").read_text()
    assert "brdf_inplane" in api and ":::" not in api


def test_the_readme_is_a_front_page():
    assert len(README.read_text().splitlines()) <= 250


def test_the_readme_links_stay_in_the_repository():
    """Every relative link of the README names a file of the repository (the README is not
    part of the site, so the site's build does not check it)."""
    text = README.read_text()
    targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text)
    relative = [t for t in targets if "://" not in t]
    assert relative
    for target in relative:
        path = (REPO / target).resolve()
        assert path.is_relative_to(REPO), target
        assert path.exists(), target


def test_the_readme_scene_is_the_start_of_the_documented_one():
    """The smallest scene of the README's tour is the first lines of the full scene in
    docs/scenes.md, which tests/test_own_data.py loads and runs."""

    def toml_blocks(text):
        return re.findall(r"```toml\n(.*?)```", text, flags=re.S)

    (small,) = toml_blocks(README.read_text())
    full = toml_blocks((REPO / "docs" / "scenes.md").read_text())
    assert any(block.startswith(small) for block in full)


def test_the_code_map_names_every_module_and_package():
    """docs/code-map.md matches the layout: every top-level module and subpackage of
    brdf_infer/ is named on it."""
    text = (REPO / "docs" / "code-map.md").read_text()
    package = REPO / "brdf_infer"
    names = [f"`{p.name}`" for p in package.glob("*.py") if p.name != "__init__.py"]
    names += [f"`{p.name}/`" for p in package.iterdir() if (p / "__init__.py").is_file()]
    missing = [name for name in names if name not in text]
    assert not missing, f"not on the code map: {missing}"
