"""Shared fixtures: the bundled scene and one reduced NUTS run (compiling NUTS takes ~15 s)."""

import os

import pytest
from hypothesis import HealthCheck, settings

import brdf_infer
from brdf_infer.posterior import run_posterior
from brdf_infer.scene import load_scene
from tests.helpers import REDUCED_NUTS

brdf_infer.use_float64()  # importing changes no JAX setting: float64 for every test

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
    "nuts_run",
    "calibration_study",
    "emcee_run",
    "batch_run",
    "abg_run",
    "traced",
    "params_export",
    "lya_fit",
    "lya_potentials",
    "image_experiment",
)
# Fixtures that sample (a NUTS or emcee run, a batch, a study): their tests are the full tier's
# (``./dev test --full``); the fast tier reads the committed run folder instead
# (tests/test_committed_run.py)
FULL_TIER_FIXTURES = (
    "nuts_run",
    "calibration_study",
    "emcee_run",
    "batch_run",
    "abg_run",
    "lya_runs",
    "lya_draws",
    "traced",
    "lya_fit",
)
# Fixtures whose tests go to another's group: the sensitivity study's report test needs both
# the study and ``nuts_run`` (a group of its own would build ``nuts_run`` on a second worker)
SAME_GROUP = {"calibration_study": "nuts_run"}


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(items):
    """Under pytest-xdist (``--dist loadgroup``), the tests sharing an expensive fixture go to
    one worker, so that it is computed once (a module fixture is otherwise built again by every
    worker that runs one of its tests). First among the hooks: pytest-xdist's worker reads the
    ``xdist_group`` marks in its own hook, which otherwise runs before this one and sees none
    (the groups were silently split across workers)."""
    for item in items:
        names = getattr(item, "fixturenames", ())
        if any(name in names for name in FULL_TIER_FIXTURES):
            item.add_marker(pytest.mark.full)
        shared = next((name for name in SHARED_FIXTURES if name in names), None)
        if shared is not None:
            item.add_marker(pytest.mark.xdist_group(SAME_GROUP.get(shared, shared)))


@pytest.hookimpl(trylast=True)
def pytest_collection_finish(session):
    """Refuse to run when ``--dist loadgroup`` has not put its group into the ids of the tests
    it groups (pytest-xdist renames them in its own collection hook): the shared fixtures would
    be built again on every worker, which costs minutes and says nothing."""
    if not session.config.getoption("loadgroup", default=False):
        return
    grouped = [item for item in session.items if item.get_closest_marker("xdist_group")]
    if grouped and not any("@" in item.nodeid for item in grouped):
        raise pytest.UsageError(
            "pytest-xdist's --dist loadgroup did not group the tests (pytest "
            f"{pytest.__version__}); install the versions pyproject.toml asks for"
        )


@pytest.fixture(scope="session")
def lya():
    scene = load_scene("lya")
    return scene, scene.load_measurements()


@pytest.fixture
def width_refit_off(monkeypatch):
    """Posterior runs in this test write their width records without NUTS refits, as batch
    scenes and a study's extra posteriors do (``refit=False``: a variant whose reweighting has
    Pareto k̂ > 0.7 is reported with its k̂ and no interval). For tests that check no width
    record: a refit is a whole NUTS run of a variant model, a program of its own to compile
    (on lya the angle errors' k̂ ≈ 6.6 refits every run; a run of few draws refits all three
    variants). As ``nuts_run``; the main job's test (tests/test_cli.py) keeps the refits and
    checks them."""
    import brdf_infer.posterior._answer as answer

    # `answer_records` asks `_refit` for the refitting function; None is the refit=False path
    monkeypatch.setattr(answer, "_refit", lambda draws, seed, tis_angles: None)


@pytest.fixture(scope="session")
def nuts_run(lya, tmp_path_factory):
    """The default scene's posterior with reduced NUTS settings, written to a folder; its width
    records without NUTS refits (``refit=False``: the angle errors' variant, k̂ ≈ 6.6, is
    reported unreliable), which would be a second NUTS run of another program in the setup
    of every test here: the main job's test (tests/test_cli.py) checks the refits."""
    out = tmp_path_factory.mktemp("nuts")
    return run_posterior(*lya, sampler="nuts", out=out, progress=False, refit=False, **REDUCED_NUTS)
