"""Importing the package changes nothing in the process: no import hook on
``sys.meta_path``, no JAX setting (float64, the compilation cache), and the old flat module
paths (CHANGELOG.md) no longer import."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

PROBE = """
import json, sys
import jax
before = (list(map(repr, sys.meta_path)), jax.config.jax_enable_x64,
          jax.config.jax_enable_compilation_cache, jax.config.jax_compilation_cache_dir)
import brdf_infer, brdf_infer.posterior, brdf_infer.scene, brdf_infer.workflow
after = (list(map(repr, sys.meta_path)), jax.config.jax_enable_x64,
         jax.config.jax_enable_compilation_cache, jax.config.jax_compilation_cache_dir)
try:
    import brdf_infer.lsq
    old = True
except ModuleNotFoundError:
    old = False
print(json.dumps({"same": before == after, "old": old}))
"""


@pytest.mark.full
def test_importing_the_package_changes_nothing_in_the_process():
    """A fresh interpreter: ``sys.meta_path``, ``jax_enable_x64`` and the compilation-cache
    settings are the same after importing the package and three of its subpackages as
    before; ``import brdf_infer.lsq`` (a path that moved) fails."""
    out = subprocess.run(
        [sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=300, check=True
    ).stdout
    result = json.loads(out.strip().splitlines()[-1])
    assert result == {"same": True, "old": False}


def test_the_top_level_names_the_python_guides_entry_points():
    """``brdf_infer.NAME`` is the entry point where it lives, for every name of ``__all__``;
    an unknown name is an AttributeError naming it."""
    import importlib

    import brdf_infer

    for name, module in brdf_infer._ENTRY_POINTS.items():
        assert getattr(brdf_infer, name) is getattr(importlib.import_module(module), name)
    assert all(hasattr(brdf_infer, name) for name in brdf_infer.__all__)
    assert sorted(dir(brdf_infer)) == sorted(brdf_infer.__all__)
    with pytest.raises(AttributeError, match="'no_such_entry'"):
        brdf_infer.no_such_entry  # noqa: B018
