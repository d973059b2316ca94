"""Shared fixtures: the bundled scene and one reduced NUTS run (compiling NUTS takes ~15 s)."""

import pytest

import brdf_infer  # noqa: F401  (float64 for every test)
from brdf_infer.posterior import run_posterior
from brdf_infer.scene import load_scene

REDUCED_NUTS = {"chains": 4, "warmup": 300, "draws": 300}


@pytest.fixture(scope="session")
def lya():
    scene = load_scene("lya")
    return scene, scene.load_measurements()


@pytest.fixture(scope="session")
def nuts_run(lya, tmp_path_factory):
    """The default scene's posterior with reduced NUTS settings, written to a folder."""
    out = tmp_path_factory.mktemp("nuts")
    return run_posterior(*lya, sampler="nuts", out=out, progress=False, **REDUCED_NUTS)
