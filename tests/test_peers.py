"""The PyMC peer model of the benchmark (``benchmarks._peers``): the same posterior as
ours, checked through its log density (no sampling)."""

import dataclasses

import numpy as np
import pytest

pytest.importorskip("pymc", reason="the peers extra is not installed")
pytest.importorskip("nutpie", reason="the peers extra is not installed")

from benchmarks._peers_check import POINTS, log_density_check, relative_spread
from brdf_infer.scene import load_scene


def _check(scene) -> None:
    ours, theirs = log_density_check(scene, scene.load_measurements())
    assert ours.shape == (POINTS,)
    assert np.all(np.isfinite(ours)) and np.all(np.isfinite(theirs))
    assert np.ptp(ours) > 1.0  # the points differ, so a constant difference means something
    assert relative_spread(ours, theirs) < 1e-8


def test_log_density_equals_ours_up_to_a_constant():
    _check(load_scene("lya"))


def test_log_density_with_fold_and_fixed_hyperparameters():
    """Eq. (10)'s fold (a constant in ln R, not in the angle slopes) and fixed α, θs0."""
    scene = load_scene("lya-fixed")
    _check(dataclasses.replace(scene, model=dataclasses.replace(scene.model, fold=True)))


def test_relative_spread_sees_a_changed_density():
    ours = np.array([-10.0, -200.0, -3000.0])
    assert relative_spread(ours, ours + 5.0) == 0.0
    assert relative_spread(ours, ours * (1 + 1e-6)) > 1e-8
