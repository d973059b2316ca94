"""``brdf-infer predict``: the model's prediction of every measurement row under an
instrument model (Eq. 6 ``point``, or the ``aperture`` / ``image`` kernels).

The package is what a parameter set predicts for a scene's rows: :func:`predict_rows` here, and
``observations``, the observation model (parameters → predicted ln R of each row), the one
forward path of every fit, the posterior and the simulations.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from brdf_infer._internal.precision import ensure_float64
from brdf_infer.model.params import Params, params_to_dict
from brdf_infer.predict.observations import build_observation_model
from brdf_infer.scene import Scene, check_instrument
from brdf_infer.tables.measurements import Measurements


def predict_rows(
    scene: Scene, measurements: Measurements, params: Params, instrument: str | None = None
) -> dict[str, Any]:
    """The predicted value of every row (raw reflectance dPs/Pi or the Eq. (2) image ratio
    for raw-reflectance series [-], the BRDF [sr⁻¹] for ``brdf`` series).

    Args:
        scene: the scene (its ``[model]`` switches and series geometry).
        measurements: the rows.
        params: Eq. (7) parameters (paper units).
        instrument: ``point``, ``aperture`` or ``image`` (default: the scene's).

    Returns:
        ``{"instrument", "params", "rows": [{"series", "sample", "theta_i_deg",
        "theta_s_deg", "predicted", "measured"}]}`` (the ``predict --json`` contract).

    Raises:
        BadInputError: an instrument model the scene's geometry cannot support.
    """
    ensure_float64()
    instrument = instrument or scene.instrument.model
    scene = check_instrument(scene, instrument)
    predicted = np.exp(
        np.asarray(build_observation_model(scene, measurements).log_reflectance(params))
    )
    rows = [
        {
            "series": str(measurements.series[k]),
            "sample": str(measurements.sample[k]),
            "theta_i_deg": float(measurements.theta_i_deg[k]),
            "theta_s_deg": float(measurements.theta_s_deg[k]),
            "predicted": float(predicted[k]),
            "measured": float(measurements.reflectance[k]),
        }
        for k in range(measurements.theta_i_deg.size)
    ]
    return {"instrument": instrument, "params": params_to_dict(params), "rows": rows}
