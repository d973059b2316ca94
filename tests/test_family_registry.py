"""One pipeline for every model family: what sets ``strumik2024`` apart is said by the family
registry (:class:`brdf_infer.model.ModelFamily`'s capabilities), never by comparing a family's
name with it elsewhere."""

import ast
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

from brdf_infer.model import FAMILIES, family, log_brdf_hemisphere, log_brdf_inplane, log_tis
from brdf_infer.model.params import PAPER_CONSTANTS, UV_PAPER

ROOT = Path(__file__).resolve().parent.parent
REGISTRY = {"brdf_infer/model/_families.py", "brdf_infer/model/__init__.py"}


def _compares_with_the_name(node: ast.AST) -> bool:
    """``x == "strumik2024"`` (or ``!=``, ``in``, …): a branch on the family's name."""
    if not isinstance(node, ast.Compare):
        return False
    operands = [node.left, *node.comparators]
    return any(isinstance(o, ast.Constant) and o.value == "strumik2024" for o in operands)


def reference_family_uses(root: Path) -> list[str]:
    """``file:line`` of every use of the name ``REFERENCE_FAMILY``, and of every comparison
    with the string ``"strumik2024"``, outside the registry."""
    found = []
    for path in sorted((root / "brdf_infer").rglob("*.py")):
        relative = path.relative_to(root).as_posix()
        if relative in REGISTRY:
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            named = (isinstance(node, ast.Name) and node.id == "REFERENCE_FAMILY") or (
                isinstance(node, ast.alias) and node.name == "REFERENCE_FAMILY"
            )
            if named or _compares_with_the_name(node):
                found.append((relative, node.lineno))
    return [f"{path}:{line}" for path, line in sorted(set(found))]


def test_no_module_outside_the_registry_names_the_reference_family():
    assert reference_family_uses(ROOT) == []


def test_the_check_finds_a_planted_branch(tmp_path):
    """Planted fault: a module that branches on the reference family's name."""
    package = tmp_path / "brdf_infer" / "report"
    package.mkdir(parents=True)
    (package / "_planted.py").write_text(
        "from brdf_infer.model import REFERENCE_FAMILY\n\n\n"
        "def label(name):\n    return '' if name == REFERENCE_FAMILY else name\n\n\n"
        "def other(attrs):\n    return attrs.get('model') != 'strumik2024'\n"
    )
    assert reference_family_uses(tmp_path) == [
        "brdf_infer/report/_planted.py:1",
        "brdf_infer/report/_planted.py:5",
        "brdf_infer/report/_planted.py:9",
    ]


@pytest.mark.full
@pytest.mark.parametrize("fold", [False, True])
def test_eq7_family_is_eq7_along_the_shared_path(fold):
    """The registry's ``strumik2024`` gives Eqs. (7), (8), (9) exactly (the same functions)."""
    member = family("strumik2024", fold, PAPER_CONSTANTS)
    physical = UV_PAPER._asdict()
    assert member.paper_parameters and member.fold is fold
    theta_i, theta_s = jnp.array([10.0, 45.0, 70.0]), jnp.array([-30.0, 20.0, 80.0])
    np.testing.assert_array_equal(
        member.log_brdf_signed(theta_i, theta_s, physical),
        log_brdf_inplane(theta_i, theta_s, UV_PAPER, fold, PAPER_CONSTANTS),
    )
    phi = jnp.array([0.0, 150.0, 180.0])
    rows = member.log_brdf_rows(theta_i, jnp.abs(theta_s), physical, phi)
    np.testing.assert_array_equal(
        rows, log_brdf_hemisphere(theta_i, jnp.abs(theta_s), phi, UV_PAPER, fold, PAPER_CONSTANTS)
    )
    np.testing.assert_array_equal(
        member.log_tis_draws(np.array([70.0]), physical),
        log_tis(np.array([70.0]), UV_PAPER, fold, PAPER_CONSTANTS),
    )
    assert member.with_fold(not fold).fold is (not fold)


@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_other_families_have_no_eq7_capabilities(name):
    member = family(name)
    assert not member.paper_parameters and not member.fold
    assert member.log_tis_draws is None and member.log_brdf_inplane is None
    assert member.with_fold(False) is member
    with pytest.raises(ValueError, match=r"no Eq\. \(10\)"):
        member.with_fold(True)


def test_a_posterior_model_refuses_an_eq7_family_folded_otherwise_than_its_scene(lya):
    """The run records the scene's fold and constants; the likelihood must use the same."""
    from brdf_infer.posterior import build_posterior_model

    scene, rows = lya
    other = family("strumik2024", not scene.model.fold, scene.model.constants)
    with pytest.raises(ValueError, match="fold and constants"):
        build_posterior_model(scene, rows, other)
    same = family("strumik2024", scene.model.fold, scene.model.constants)
    assert build_posterior_model(scene, rows, same).family.fold == scene.model.fold
