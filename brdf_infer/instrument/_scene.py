"""A scene's kernel: its rows, its series' beam geometries and its ``[instrument]`` table."""

from __future__ import annotations

import numpy as np

from brdf_infer.errors import BadInputError
from brdf_infer.instrument._geometry import BeamGeometry
from brdf_infer.instrument._kernel import Kernel, row_kernels


def beam_geometry(scene, series: str) -> BeamGeometry | None:
    """The :class:`BeamGeometry` of a series of ``scene`` (None without one)."""
    setup = scene.setup_of(series)
    detector = scene.series[series]
    if setup is None or detector.aperture_diameter_mm is None:
        return None
    return BeamGeometry(
        source_radius=setup.source_diameter_mm / 2,
        source_distance=setup.source_distance_mm,
        beam_aperture_radii=tuple(d / 2 for d, _ in setup.beam_apertures_mm),
        beam_aperture_distances=tuple(z for _, z in setup.beam_apertures_mm),
        sample_half_size=(setup.sample_size_mm[0] / 2, setup.sample_size_mm[1] / 2),
        aperture_radius=detector.aperture_diameter_mm / 2,
        aperture_distance=detector.aperture_distance_mm,
        detector_behind=setup.detector_behind_aperture_mm,
        signal_half_size=(setup.signal_region_mm[0] / 2, setup.signal_region_mm[1] / 2),
    )


def build_kernel(scene, measurements, instrument: str | None = None) -> Kernel | None:
    """The kernel of every row of ``measurements`` under ``scene``'s instrument model (or
    ``instrument``); None for ``point``. Rows of a ``brdf`` series keep their own value.

    Raises:
        BadInputError: a row of an out-of-plane measurement (the kernel is built for the
            plane of incidence), or a row no scattered light reaches under this geometry.
    """
    model = instrument or scene.instrument.model
    if model == "point":
        return None
    geometries = {name: beam_geometry(scene, name) for name in scene.series}
    rows = []
    for index, name in enumerate(measurements.series):
        geometry = geometries[name] if scene.series[name].quantity == "raw_reflectance" else None
        out_of_plane = measurements.phi_s_deg is not None and np.isfinite(
            measurements.phi_s_deg[index]
        )
        if geometry is not None and out_of_plane:
            raise BadInputError(
                f"instrument model {model!r} is built for detectors in the plane of "
                "incidence; this row is out of it",
                file=scene.measurements_path,
                row=index + 1,
                field="phi_s_deg",
            )
        rows.append(geometry)
    kernel = row_kernels(
        measurements.theta_i_deg,
        measurements.theta_s_deg,
        rows,
        model,
        scene.instrument.nodes,
        scene.instrument.candidates,
    )
    empty = np.flatnonzero((np.asarray(kernel.weight).sum(axis=1) <= 0) & (kernel.applies > 0))
    if empty.size:
        raise BadInputError(
            f"under instrument model {model!r} no scattered light reaches the detector "
            f"(θi = {measurements.theta_i_deg[empty[0]]:g}°, "
            f"θs = {measurements.theta_s_deg[empty[0]]:g}°): check the [instrument] geometry",
            file=scene.measurements_path,
            row=int(empty[0]) + 1,
        )
    return kernel
