"""Parameter-independent nodes of one measurement: where the setup samples the BRDF.

A measured raw reflectance is not the BRDF at one (θi, θs) times Ω·cos θs (Eq. 6, the
``point`` instrument): the source disk and the beam apertures spread the incidence over a
footprint on the sample, and the detector aperture AD collects a bundle of directions. With
the beam's radiant intensity ``b`` (relative weight cos⁴ψ of a ray at angle ψ to the axis,
only rays through every beam aperture), the power scattered through AD is

    dPs/Pi = ∫ b ∫_AD BRDF(θi(x), θ(x, a), φ(x, a)) cos θ_out cos θ_AD / |a − x|² da dbeam / ∫ b,

x the ray's hit point on the sample (zero outside it), a a point of AD. Every factor but the
BRDF depends on the geometry alone, so a fixed cubature over (source point, limiting-aperture
point, AD point) gives nodes (θi_k, θ_k, φ_k) and weights w_k with dPs/Pi = Σ w_k BRDF_k —
the ``aperture`` instrument. The ``image`` instrument is the paper's Eq. (2) as applied to CCD
frames: the scattered power landing in the signal rectangle of the detector plane (``behind``
AD, along the straight continuation x → a) over the reference beam's power in the same
rectangle, the reference being the beam straight into AD and the detector at the same
source distance (Sec. 3.1).

Lab frame (that of ``brdf_infer.studies.raytrace``, written separately from it in NumPy so each
checks the other): sample in z = 0, normal +z, plane of incidence x–z, forward side +x
(φ = 180° of Eq. 8), source towards (−sin θi, 0, cos θi), AD centre at r·(sin θs, 0, cos θs).
Lengths in mm, angles in degrees.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import qmc

from brdf_infer._internal.units import DEG

NODE_DIMENSIONS = 6  # source disk (2), limiting beam aperture (2), detector aperture (2)
SOBOL_SEED = 20240121  # fixed: the kernel is a deterministic cubature


@dataclass(frozen=True)
class BeamGeometry:
    """The setup of one measurement series [mm] (Sec. 2, Fig. 12).

    Attributes:
        source_radius: radius of the source disk.
        source_distance: source – sample-centre distance along the beam axis.
        beam_aperture_radii: radii of the beam apertures.
        beam_aperture_distances: their distances from the source.
        sample_half_size: half sides of the sample (in the plane of incidence, across).
        aperture_radius: radius of the detector aperture AD.
        aperture_distance: AD – sample-centre distance r.
        detector_behind: detector plane behind AD.
        signal_half_size: half sides of the signal rectangle on the detector plane.
    """

    source_radius: float
    source_distance: float
    beam_aperture_radii: tuple[float, ...]
    beam_aperture_distances: tuple[float, ...]
    sample_half_size: tuple[float, float]
    aperture_radius: float
    aperture_distance: float
    detector_behind: float
    signal_half_size: tuple[float, float]


@dataclass(frozen=True)
class Nodes:
    """Nodes of one measurement (arrays of one length).

    Attributes:
        theta_i_deg: local incidence angle of each node [deg].
        theta_deg: polar scattering angle [deg].
        phi_deg: azimuth from the backward half of the node's own plane of incidence
            (forward = 180°) [deg].
        aperture_weight: w_k of dPs/Pi through AD [sr] (Σ w_k BRDF_k).
        image_weight: w_k of the Eq. (2) image ratio over the signal rectangle [sr].
    """

    theta_i_deg: np.ndarray
    theta_deg: np.ndarray
    phi_deg: np.ndarray
    aperture_weight: np.ndarray
    image_weight: np.ndarray


def sobol_uniforms(count: int) -> np.ndarray:
    """``count`` scrambled Sobol points in [0, 1)⁶ (fixed seed; a power of two is best)."""
    sampler = qmc.Sobol(d=NODE_DIMENSIONS, scramble=True, seed=SOBOL_SEED)
    return sampler.random(count)


def _disk(u_radius: np.ndarray, u_angle: np.ndarray, radius: float) -> tuple[np.ndarray, ...]:
    r = radius * np.sqrt(u_radius)
    return r * np.cos(2 * np.pi * u_angle), r * np.sin(2 * np.pi * u_angle)


def _inside(x: np.ndarray, y: np.ndarray, half: tuple[float, float]) -> np.ndarray:
    return (np.abs(x) <= half[0]) & (np.abs(y) <= half[1])


def measurement_nodes(
    theta_i_deg: float, theta_s_deg: float, geometry: BeamGeometry, uniforms: np.ndarray
) -> Nodes:
    """Nodes and weights of the measurement at nominal (θi, θs) (module docstring).

    Args:
        theta_i_deg: nominal incidence angle (beam axis to sample normal) [deg].
        theta_s_deg: nominal detector angle, signed in the plane of incidence [deg].
        geometry: the series' setup.
        uniforms: (N, 6) points of [0, 1)⁶, e.g. :func:`sobol_uniforms`.
    """
    g = geometry
    radii = np.asarray(g.beam_aperture_radii)
    distances = np.asarray(g.beam_aperture_distances)
    limiting = int(np.argmin(radii / distances))
    p1, p2 = _disk(uniforms[:, 0], uniforms[:, 1], g.source_radius)
    q1, q2 = _disk(uniforms[:, 2], uniforms[:, 3], radii[limiting])
    t1, t2 = (q1 - p1) / distances[limiting], (q2 - p2) / distances[limiting]
    at_x = p1[:, None] + t1[:, None] * distances
    at_y = p2[:, None] + t2[:, None] * distances
    passes = np.all(at_x**2 + at_y**2 <= radii**2 * (1 + 1e-12), axis=1)
    beam = np.where(passes, (1.0 + t1**2 + t2**2) ** -2, 0.0)  # cos⁴ψ

    sin_i, cos_i = np.sin(theta_i_deg * DEG), np.cos(theta_i_deg * DEG)
    axis = np.array([sin_i, 0.0, -cos_i])
    e1, e2 = np.array([cos_i, 0.0, sin_i]), np.array([0.0, 1.0, 0.0])
    origin = -g.source_distance * axis + p1[:, None] * e1 + p2[:, None] * e2
    direction = axis + t1[:, None] * e1 + t2[:, None] * e2
    hit = origin - (origin[:, 2] / direction[:, 2])[:, None] * direction
    on_sample = _inside(hit[:, 0], hit[:, 1], g.sample_half_size)

    sin_s, cos_s = np.sin(theta_s_deg * DEG), np.cos(theta_s_deg * DEG)
    towards = np.array([sin_s, 0.0, cos_s])
    in_plane = np.array([cos_s, 0.0, -sin_s])
    a1, a2 = _disk(uniforms[:, 4], uniforms[:, 5], g.aperture_radius)
    point = g.aperture_distance * towards + a1[:, None] * in_plane + a2[:, None] * e2
    path = point - hit
    length = np.linalg.norm(path, axis=1)
    omega = path / length[:, None]
    cos_out, cos_ad = omega[:, 2], omega @ towards
    valid = on_sample & (cos_out > 0) & (cos_ad > 0) & (beam > 0)
    geometric = np.where(valid, cos_out * cos_ad, 0.0) * np.pi * g.aperture_radius**2 / length**2

    unit_in = direction / np.linalg.norm(direction, axis=1, keepdims=True)
    theta_i = np.degrees(np.arccos(np.clip(-unit_in[:, 2], -1.0, 1.0)))
    theta = np.degrees(np.arccos(np.clip(omega[:, 2], -1.0, 1.0)))
    cross = omega[:, 0] * unit_in[:, 1] - omega[:, 1] * unit_in[:, 0]
    dot = omega[:, 0] * unit_in[:, 0] + omega[:, 1] * unit_in[:, 1]
    phi = 180.0 - np.degrees(np.arctan2(np.abs(cross), dot))

    landing = point + (g.detector_behind / np.where(valid, cos_ad, 1.0))[:, None] * omega
    offset = landing - (g.aperture_distance + g.detector_behind) * towards
    in_signal = _inside(offset @ in_plane, offset[:, 1], g.signal_half_size)
    reference_aperture = g.source_distance + g.aperture_distance
    reference_detector = reference_aperture + g.detector_behind
    through = (p1 + t1 * reference_aperture) ** 2 + (
        p2 + t2 * reference_aperture
    ) ** 2 <= g.aperture_radius**2
    reference_signal = through & _inside(
        p1 + t1 * reference_detector, p2 + t2 * reference_detector, g.signal_half_size
    )
    beam_total = beam.sum()
    reference_total = (beam * reference_signal).sum()
    scattered = beam * geometric
    return Nodes(
        theta_i_deg=theta_i,
        theta_deg=theta,
        phi_deg=phi,
        aperture_weight=scattered / beam_total,
        image_weight=(
            np.where(in_signal, scattered, 0.0) / reference_total
            if reference_total > 0
            else np.zeros_like(scattered)
        ),
    )
