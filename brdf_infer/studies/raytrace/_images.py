"""Simulated detector images of the series II setup (Fig. 13)."""

from __future__ import annotations

import jax
import numpy as np

from brdf_infer.model.params import Params
from brdf_infer.scene import Scene
from brdf_infer.studies.raytrace._setup import build_setup, configurations
from brdf_infer.studies.raytrace._trace import detector_images
from brdf_infer.tables.measurements import Measurements


def simulate_images(
    scene: Scene,
    measurements: Measurements,
    params: Params,
    rays: int = 2**18,
    seed: int = 0,
    bins: tuple[int, int] = (128, 32),
) -> dict:
    """Detector images at the scene's ``image_theta_i_deg`` for every detector angle measured
    there (Fig. 13): scattered and reference power per pixel, and the pixel edges [mm]."""
    setup, limiting = build_setup(scene)
    theta_i = scene.raytrace.image_theta_i_deg
    angles = sorted(
        {c.theta_s_deg for c in configurations(scene, measurements) if c.theta_i_deg == theta_i}
    ) or [theta_i]
    key = jax.random.PRNGKey(seed)
    images, reference = [], None
    for theta_s in angles:
        scattered, reference = detector_images(
            key,
            theta_i,
            theta_s,
            params,
            setup,
            scene.model.constants,
            rays,
            "nee",
            limiting,
            bins,
            scene.model.fold,
        )
        images.append(np.asarray(scattered))
    half = np.asarray(setup.detector_half_size)
    return {
        "theta_i_deg": theta_i,
        "theta_s_deg": angles,
        "scattered": np.stack(images),
        "reference": np.asarray(reference),
        "x_edges_mm": np.linspace(-half[0], half[0], bins[0] + 1),
        "y_edges_mm": np.linspace(-half[1], half[1], bins[1] + 1),
        "signal_half_size_mm": np.asarray(setup.signal_half_size),
    }
