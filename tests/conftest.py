"""Shared fixtures: the bundled scene and one reduced NUTS run (compiling NUTS takes ~15 s)."""

import os

import pytest
from hypothesis import HealthCheck, settings

import brdf_infer  # noqa: F401  (float64 for every test)
from brdf_infer.posterior import run_posterior
from brdf_infer.scene import load_scene
from tests.helpers import REDUCED_NUTS

# Property tests: random exploration locally; CI (the CI variable set, as .ci/run does)
# replays the same examples every time so a run cannot fail by chance; "explore" searches
# long (HYPOTHESIS_PROFILE=explore ./dev test tests/test_stability.py).
_PROPERTY_DEFAULTS = {"deadline": None, "suppress_health_check": [HealthCheck.too_slow]}
settings.register_profile("dev", max_examples=60, **_PROPERTY_DEFAULTS)
settings.register_profile("ci", max_examples=60, derandomize=True, **_PROPERTY_DEFAULTS)
settings.register_profile("explore", max_examples=2000, **_PROPERTY_DEFAULTS)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci" if os.environ.get("CI") else "dev"))


# Fixtures computed once per module or session whose work is worth sharing (a NUTS or emcee
# run, a batch, ray traces, a least-squares fit, compiled potentials), most shared first.
SHARED_FIXTURES = (
    "calibration_study",  # before nuts_run: its report test needs both
    "nuts_run",
    "emcee_run",
    "batch_run",
    "abg_run",
    "traced",
    "params_export",
    "lya_fit",
    "lya_potentials",
    "image_experiment",
)


def pytest_collection_modifyitems(items):
    """Under pytest-xdist (``--dist loadgroup``), the tests sharing an expensive fixture go to
    one worker, so that it is computed once (a module fixture is otherwise built again by every
    worker that runs one of its tests)."""
    for item in items:
        names = getattr(item, "fixturenames", ())
        shared = next((name for name in SHARED_FIXTURES if name in names), None)
        if shared is not None:
            item.add_marker(pytest.mark.xdist_group(shared))


@pytest.fixture(scope="session")
def lya():
    scene = load_scene("lya")
    return scene, scene.load_measurements()


@pytest.fixture(scope="session")
def nuts_run(lya, tmp_path_factory):
    """The default scene's posterior with reduced NUTS settings, written to a folder."""
    out = tmp_path_factory.mktemp("nuts")
    return run_posterior(*lya, sampler="nuts", out=out, progress=False, **REDUCED_NUTS)
