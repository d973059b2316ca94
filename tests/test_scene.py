"""Scene loading: the minimal form of docs/scenes.md, defaults and the bundled scene."""

from brdf_infer.scene import load_scene
from tests.test_bad_input import GOOD_ROWS, HEADER, SCENE, write_scene


def test_minimal_design_form_loads_with_defaults(tmp_path):
    scene = load_scene(write_scene(tmp_path, "\n".join([HEADER, *GOOD_ROWS]) + "\n", SCENE))
    assert scene.name == "tiny" and scene.errors.reflectance_rel == 0.065
    assert scene.errors.angle_deg == 1.0 and scene.model.fold is False
    assert len(scene.load_measurements()) == 5


def test_bundled_scene_has_both_series_geometries():
    scene = load_scene()
    assert scene.name == "lya"
    assert scene.series["I"].aperture_diameter_mm == 7.2
    assert scene.series["I"].aperture_distance_mm == 103.8
    assert scene.series["II"].aperture_diameter_mm == 7.5
    assert scene.series["II"].aperture_distance_mm == 110.0
    measurements = scene.load_measurements()
    assert len(measurements) == 24 + 18
    assert set(measurements.sample[measurements.series == "I"]) == {"1", "2", "3", "4", "5", "6"}
