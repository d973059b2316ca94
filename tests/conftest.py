"""Shared fixtures: the bundled scene and one reduced NUTS run (compiling NUTS takes ~15 s)."""

import os

import pytest
from hypothesis import HealthCheck, settings

import brdf_infer  # noqa: F401  (float64 for every test)
from brdf_infer.posterior import run_posterior
from brdf_infer.scene import load_scene

# 1000 draws: under the default error model the learned noise scales reach down to 0 (series
# II's values carry their own σ), and 4 × 500 draws gave them a tail ESS of 283-375 for some
# seeds; the draws do not change the compiled program (the warmup does)
REDUCED_NUTS = {"chains": 4, "warmup": 500, "draws": 1000}

# Property tests: random exploration locally; CI (the CI variable set, as .ci/run does)
# replays the same examples every time so a run cannot fail by chance; "explore" searches
# long (HYPOTHESIS_PROFILE=explore ./dev test tests/test_stability.py).
_PROPERTY_DEFAULTS = {"deadline": None, "suppress_health_check": [HealthCheck.too_slow]}
settings.register_profile("dev", max_examples=60, **_PROPERTY_DEFAULTS)
settings.register_profile("ci", max_examples=60, derandomize=True, **_PROPERTY_DEFAULTS)
settings.register_profile("explore", max_examples=2000, **_PROPERTY_DEFAULTS)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci" if os.environ.get("CI") else "dev"))


def pytest_collection_modifyitems(items):
    """Under pytest-xdist (``--dist loadgroup``), the tests sharing a session run go to one
    worker, so that run is computed once."""
    for item in items:
        for shared in ("nuts_run", "emcee_run"):
            if shared in getattr(item, "fixturenames", ()):
                item.add_marker(pytest.mark.xdist_group(shared))
                break


@pytest.fixture(scope="session")
def lya():
    scene = load_scene("lya")
    return scene, scene.load_measurements()


@pytest.fixture(scope="session")
def nuts_run(lya, tmp_path_factory):
    """The default scene's posterior with reduced NUTS settings, written to a folder."""
    out = tmp_path_factory.mktemp("nuts")
    return run_posterior(*lya, sampler="nuts", out=out, progress=False, **REDUCED_NUTS)
