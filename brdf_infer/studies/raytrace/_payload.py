"""The JSON objects of ``brdf-infer raytrace``: a ray-traced series with the parameters traced,
where they came from and the scene file."""

from __future__ import annotations

import numpy as np

from brdf_infer.model.params import Params, params_to_dict
from brdf_infer.scene import Scene
from brdf_infer.studies.raytrace._series import RaytraceResult, raytrace_posterior, raytrace_series
from brdf_infer.tables.measurements import Measurements


def _payload(scene: Scene, result: RaytraceResult, params: Params, source: str, draws) -> dict:
    return {
        **result.as_json(),
        "series": scene.raytrace.series,
        "params": params_to_dict(params),
        "params_source": source,
        "draws": draws,
        "scene_file": str(scene.path),
    }


def raytrace_payload(
    scene: Scene,
    measurements: Measurements,
    params: Params,
    source: str,
    rays: int | None = None,
    seed: int = 0,
    estimator: str = "nee",
    progress=None,
) -> dict:
    """:func:`raytrace_series` as the JSON object of ``brdf-infer raytrace --json``, with the
    parameters traced, where they came from (``source``) and the scene file."""
    result = raytrace_series(scene, measurements, params, rays, seed, estimator, progress)
    return _payload(scene, result, params, source, None)


def raytrace_posterior_payload(
    scene: Scene,
    measurements: Measurements,
    draws: Params,
    source: str,
    rays: int = 16_384,
    seed: int = 0,
    progress=None,
) -> dict:
    """:func:`raytrace_posterior` as the JSON object of ``brdf-infer raytrace --run``;
    ``params`` is the representative draw."""
    result, representative = raytrace_posterior(scene, measurements, draws, rays, seed, progress)
    return _payload(scene, result, representative, source, int(np.size(draws.brdf0)))
