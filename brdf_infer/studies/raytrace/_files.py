"""The ray traces of a run folder: ``raytrace.json`` (the traced series, one entry per
parameter source) and ``detector_images.npz`` (the simulated detector images of the first
entry, Fig. 13), written atomically by whatever traces (``run``, ``raytrace --out``) and read
by the report, which computes nothing."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from brdf_infer.errors import BadInputError
from brdf_infer.model.params import Params
from brdf_infer.runs.folder import DETECTOR_IMAGES_FILE, RunFolder
from brdf_infer.scene import Scene
from brdf_infer.studies.raytrace._images import simulate_images
from brdf_infer.tables.measurements import Measurements

_ARRAYS = ("scattered", "reference", "x_edges_mm", "y_edges_mm", "signal_half_size_mm")


def write_traces(out: Path, scene: Scene, measurements: Measurements, traces: list[dict]) -> dict:
    """Write ``traces`` and the detector images of the first one into ``out``; returns the
    images (:func:`~brdf_infer.studies.raytrace.simulate_images`)."""
    images = simulate_images(
        scene, measurements, Params(**traces[0]["params"]), seed=traces[0]["seed"]
    )
    buffer = io.BytesIO()
    np.savez(
        buffer,
        theta_i_deg=np.asarray(images["theta_i_deg"], float),
        theta_s_deg=np.asarray(images["theta_s_deg"], float),
        **{name: np.asarray(images[name]) for name in _ARRAYS},
    )
    folder = RunFolder(out)
    folder.write_bytes(DETECTOR_IMAGES_FILE, buffer.getvalue())
    folder.write_traces(traces)
    return images


def load_traces(run: Path) -> list[dict]:
    """The ray traces a run wrote (``raytrace.json``), possibly none.

    Raises:
        BadInputError: the file is there but unreadable, no JSON or without ``traces``.
    """
    return RunFolder(run).traces()


def load_detector_images(run: Path) -> dict | None:
    """The detector images a run wrote (``detector_images.npz``; None: none, as in runs made
    before they were written)."""
    path = RunFolder(run).file(DETECTOR_IMAGES_FILE)
    if not path.is_file():
        return None
    try:
        with np.load(path) as stored:
            images = {name: np.asarray(stored[name]) for name in _ARRAYS}
            images["theta_i_deg"] = float(stored["theta_i_deg"])
            images["theta_s_deg"] = [float(v) for v in stored["theta_s_deg"]]
    except (OSError, ValueError, KeyError) as error:
        raise BadInputError(f"cannot read the detector images: {error}", file=path) from None
    return images
