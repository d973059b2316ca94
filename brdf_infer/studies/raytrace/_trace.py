"""Monte Carlo of the series II measurement setup (Sec. 6, Fig. 12) for one configuration.

Lab frame: the sample lies in the plane z = 0 centred on the origin, normal +z; the plane of
incidence is x–z with the specular (forward) side at +x, which is φ = 180° of Eq. (8). The
source sits at ``source_distance`` from the sample centre towards (−sin θi, 0, cos θi); the
detector aperture AD is centred at ``detector_aperture_distance`` along the detector direction
D = (sin θs, 0, cos θs) and the detector plane lies ``detector_behind_aperture`` behind it,
perpendicular to D, its long side in the plane of incidence.

One ray is sampled per source point and beam-aperture point; it carries the weight of the
beam's radiant intensity. Each ray is followed to the sample and then, by one of two
estimators, to the detector:

- ``"naive"``: a direction drawn from the cosine-weighted hemisphere with weight π·BRDF
  (importance sampling of Eq. (9)'s integrand, exact, no grid), counted when it passes AD and
  reaches the detector plane — the paper's forward ray trace;
- ``"nee"``: next-event estimation, a point drawn uniformly on AD and the contribution
  BRDF·cos θ·cos θ_AD·A_AD/d² of that path (the exact power through AD for this source point),
  counted on the detector where the straight continuation lands. Unbiased for the same
  tallies, with a far smaller variance because every ray contributes.

The reference measurement follows the same rays straight on with no sample, with AD and the
detector plane at the same source distance as in the measurement (Sec. 3.1).
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp

from brdf_infer._internal.units import DEG
from brdf_infer.model import log_brdf_hemisphere
from brdf_infer.model.params import HemisphereConstants, Params

ESTIMATORS: tuple[str, ...] = ("nee", "naive")

# Per-ray tallies, in this order (each carries the ray's beam weight):
TALLIES: tuple[str, ...] = (
    "beam",  # the incident beam: weight of every ray that leaves the beam apertures
    "aperture",  # scattered power through AD
    "detector",  # scattered power through AD that reaches the detector rectangle
    "signal",  # ... that lands in the signal rectangle
    "reference_detector",  # reference beam through AD onto the detector rectangle
    "reference_signal",  # reference beam in the signal rectangle
)


class Setup(NamedTuple):
    """Lengths of the setup [mm], a JAX pytree (changing them does not recompile).

    Attributes:
        source_radius: radius of the source disk.
        source_distance: source–sample-centre distance along the beam axis.
        beam_aperture_radii: radii of the beam apertures A1, A2, …
        beam_aperture_distances: their distances from the source along the axis.
        sample_half_size: half side lengths of the sample (x in the plane of incidence, y).
        aperture_radius: radius of the detector aperture AD.
        aperture_distance: AD–sample-centre distance.
        detector_behind: distance of the detector plane behind AD.
        detector_half_size: half sides of the detector rectangle (in-plane, perpendicular).
        signal_half_size: half sides of the signal rectangle centred on the detector axis.
    """

    source_radius: jnp.ndarray
    source_distance: jnp.ndarray
    beam_aperture_radii: jnp.ndarray
    beam_aperture_distances: jnp.ndarray
    sample_half_size: jnp.ndarray
    aperture_radius: jnp.ndarray
    aperture_distance: jnp.ndarray
    detector_behind: jnp.ndarray
    detector_half_size: jnp.ndarray
    signal_half_size: jnp.ndarray


def _uniform_disk(key: jax.Array, n: int, radius) -> tuple[jnp.ndarray, jnp.ndarray]:
    k_radius, k_angle = jax.random.split(key)
    r = radius * jnp.sqrt(jax.random.uniform(k_radius, (n,)))
    angle = 2.0 * jnp.pi * jax.random.uniform(k_angle, (n,))
    return r * jnp.cos(angle), r * jnp.sin(angle)


def _beam(key: jax.Array, n: int, theta_i_deg, setup: Setup, limiting: int):
    """Rays of the incident beam: origin, direction (not normalised), weight, transverse
    source position and slope (beam frame) for the reference.

    The point on the limiting aperture (the one of smallest angular radius seen from the
    source) is drawn uniformly; a ray counts when it passes every aperture. The weight
    cos⁴ψ (ψ: angle to the axis) is the radiance-to-flux factor cos ψ_source·cos ψ_aperture/d²
    of a disk source facing the axis, relative to the on-axis ray.
    """
    k_source, k_aperture = jax.random.split(key)
    p1, p2 = _uniform_disk(k_source, n, setup.source_radius)
    q1, q2 = _uniform_disk(k_aperture, n, setup.beam_aperture_radii[limiting])
    length = setup.beam_aperture_distances[limiting]
    t1, t2 = (q1 - p1) / length, (q2 - p2) / length
    at_apertures = (p1[:, None] + t1[:, None] * setup.beam_aperture_distances) ** 2 + (
        p2[:, None] + t2[:, None] * setup.beam_aperture_distances
    ) ** 2
    passes = jnp.all(at_apertures <= setup.beam_aperture_radii**2 * (1 + 1e-12), axis=1)
    weight = jnp.where(passes, 1.0 / (1.0 + t1**2 + t2**2) ** 2, 0.0)

    sin_i, cos_i = jnp.sin(theta_i_deg * DEG), jnp.cos(theta_i_deg * DEG)
    axis = jnp.array([sin_i, 0.0, -cos_i])
    e1 = jnp.array([cos_i, 0.0, sin_i])  # transverse, in the plane of incidence
    e2 = jnp.array([0.0, 1.0, 0.0])
    origin = -setup.source_distance * axis + p1[:, None] * e1 + p2[:, None] * e2
    direction = axis + t1[:, None] * e1 + t2[:, None] * e2
    return origin, direction, weight, (p1, p2, t1, t2)


def _reference(transverse, setup: Setup):
    """Reference measurement: the beam straight into AD and the detector plane, placed at
    the measurement's source–detector distance. Returns (on detector, in signal rectangle)."""
    p1, p2, t1, t2 = transverse
    at_aperture = setup.source_distance + setup.aperture_distance
    at_detector = at_aperture + setup.detector_behind
    a1, a2 = p1 + t1 * at_aperture, p2 + t2 * at_aperture
    through = a1**2 + a2**2 <= setup.aperture_radius**2
    x, y = p1 + t1 * at_detector, p2 + t2 * at_detector
    on_detector = through & _inside(x, y, setup.detector_half_size)
    return on_detector, on_detector & _inside(x, y, setup.signal_half_size), (x, y)


def _inside(x, y, half_size) -> jnp.ndarray:
    return (jnp.abs(x) <= half_size[0]) & (jnp.abs(y) <= half_size[1])


def _scattering_angles(direction_in, omega):
    """Local θi, θ and φ [deg] of Eq. (8) for unit outgoing directions ω.

    φ is measured from the backward half-plane of each ray's own plane of incidence
    (forward = 180°).
    """
    unit_in = direction_in / jnp.linalg.norm(direction_in, axis=-1, keepdims=True)
    theta_i = jnp.arccos(jnp.clip(-unit_in[:, 2], -1.0, 1.0)) / DEG
    theta = jnp.arccos(jnp.clip(omega[:, 2], -1.0, 1.0)) / DEG
    cross = omega[:, 0] * unit_in[:, 1] - omega[:, 1] * unit_in[:, 0]
    dot = omega[:, 0] * unit_in[:, 0] + omega[:, 1] * unit_in[:, 1]
    psi = jnp.arctan2(jnp.abs(cross), dot) / DEG  # angle between the in-surface projections
    return theta_i, theta, 180.0 - psi


def _trace(
    key: jax.Array,
    theta_i_deg,
    theta_s_deg,
    params: Params,
    setup: Setup,
    constants: HemisphereConstants,
    n: int,
    estimator: str,
    limiting: int,
    fold: bool = False,
):
    """Per-ray tallies (n, 6) in the order of ``TALLIES`` and detector coordinates [mm];
    the BRDF is Eq. (8), with Eq. (10)'s folding when ``fold`` (the scene's switch)."""
    k_beam, k_scatter = jax.random.split(key)
    origin, direction, weight, transverse = _beam(k_beam, n, theta_i_deg, setup, limiting)
    tau = -origin[:, 2] / direction[:, 2]
    hit_point = origin + tau[:, None] * direction
    on_sample = _inside(hit_point[:, 0], hit_point[:, 1], setup.sample_half_size)

    sin_s, cos_s = jnp.sin(theta_s_deg * DEG), jnp.cos(theta_s_deg * DEG)
    detector_dir = jnp.array([sin_s, 0.0, cos_s])
    in_plane = jnp.array([cos_s, 0.0, -sin_s])  # long side of the detector
    across = jnp.array([0.0, 1.0, 0.0])
    frame = (detector_dir, in_plane, across, setup.aperture_distance * detector_dir)
    sample = (hit_point, direction, on_sample)
    if estimator == "nee":
        scattering = _next_event(k_scatter, n, sample, frame, params, setup, constants, fold)
    elif estimator == "naive":
        scattering = _forward(k_scatter, n, sample, frame, params, setup, constants, fold)
    else:
        raise ValueError(f"unknown estimator {estimator!r} (known: {', '.join(ESTIMATORS)})")
    contribution, through, omega, cos_aperture, aperture_point = scattering

    safe_cos = jnp.where(through, cos_aperture, 1.0)
    landing = aperture_point + (setup.detector_behind / safe_cos)[:, None] * omega
    relative = landing - (setup.aperture_distance + setup.detector_behind) * detector_dir
    x, y = relative @ in_plane, relative @ across
    on_detector = through & _inside(x, y, setup.detector_half_size)
    in_signal = on_detector & _inside(x, y, setup.signal_half_size)
    ref_detector, ref_signal, ref_xy = _reference(transverse, setup)
    scattered = weight * contribution
    tallies = jnp.stack(
        [
            weight,
            scattered,
            jnp.where(on_detector, scattered, 0.0),
            jnp.where(in_signal, scattered, 0.0),
            jnp.where(ref_detector, weight, 0.0),
            jnp.where(ref_signal, weight, 0.0),
        ],
        axis=1,
    )
    return tallies, (x, y), ref_xy


def _next_event(key, n: int, sample, frame, params, setup: Setup, constants, fold: bool):
    """The ``"nee"`` estimator: a point drawn uniformly on AD and the power of the path from
    the hit point through it, BRDF·cos θ·cos θ_AD·A_AD/d².

    Args:
        sample: hit points on the sample plane [mm], incident directions, and whether the
            hit point lies on the sample.
        frame: the detector direction D, the detector's in-plane and across axes, and the
            centre of AD [mm].

    Returns:
        Per ray: contribution (a fraction of its beam weight), whether it passes AD, the
        outgoing unit direction ω, cos of ω to D, and the point on AD [mm].
    """
    hit_point, direction, on_sample = sample
    detector_dir, in_plane, across, aperture_centre = frame
    a1, a2 = _uniform_disk(key, n, setup.aperture_radius)
    aperture_point = aperture_centre + a1[:, None] * in_plane + a2[:, None] * across
    path = aperture_point - hit_point
    distance = jnp.linalg.norm(path, axis=1)
    omega = path / distance[:, None]
    cos_out, cos_aperture = omega[:, 2], omega @ detector_dir
    valid = on_sample & (cos_out > 0) & (cos_aperture > 0)
    theta_i, theta, phi = _scattering_angles(direction, omega)
    log_brdf = log_brdf_hemisphere(theta_i, theta, phi, params, fold, constants)
    area = jnp.pi * setup.aperture_radius**2
    log_geometry = jnp.log(jnp.where(valid, cos_out * cos_aperture * area, 1.0)) - 2 * jnp.log(
        distance
    )
    contribution = jnp.where(valid, jnp.exp(log_brdf + log_geometry), 0.0)
    return contribution, valid, omega, cos_aperture, aperture_point


def _forward(key, n: int, sample, frame, params, setup: Setup, constants, fold: bool):
    """The ``"naive"`` estimator: a direction drawn from the cosine-weighted hemisphere with
    weight π·BRDF, counted when it passes AD. Arguments and returns as :func:`_next_event`."""
    hit_point, direction, on_sample = sample
    detector_dir, _, _, aperture_centre = frame
    u1, u2 = jax.random.uniform(key, (2, n))
    radial = jnp.sqrt(u1)
    omega = jnp.stack(
        [
            radial * jnp.cos(2 * jnp.pi * u2),
            radial * jnp.sin(2 * jnp.pi * u2),
            jnp.sqrt(1 - u1),
        ],
        axis=1,
    )
    cos_aperture = omega @ detector_dir
    facing = cos_aperture > 0
    reach = ((aperture_centre - hit_point) @ detector_dir) / jnp.where(facing, cos_aperture, 1.0)
    aperture_point = hit_point + reach[:, None] * omega
    offset = aperture_point - aperture_centre
    through = (
        on_sample & facing & (reach > 0) & (jnp.sum(offset**2, axis=1) <= setup.aperture_radius**2)
    )
    theta_i, theta, phi = _scattering_angles(direction, omega)
    log_brdf = log_brdf_hemisphere(theta_i, theta, phi, params, fold, constants)
    contribution = jnp.where(through, jnp.pi * jnp.exp(log_brdf), 0.0)
    return contribution, through, omega, cos_aperture, aperture_point


@partial(jax.jit, static_argnames=("n", "estimator", "limiting", "fold"))
def tally_moments(
    key, theta_i_deg, theta_s_deg, params, setup, constants, n, estimator, limiting, fold=False
):
    """Sums Σz and Σzzᵀ of the per-ray tallies z (shape (6,) and (6, 6)) of n rays."""
    tallies, _, _ = _trace(
        key, theta_i_deg, theta_s_deg, params, setup, constants, n, estimator, limiting, fold
    )
    return tallies.sum(axis=0), tallies.T @ tallies


@partial(jax.jit, static_argnames=("n", "estimator", "limiting", "bins", "fold"))
def detector_images(
    key, theta_i_deg, theta_s_deg, params, setup, constants, n, estimator, limiting, bins, fold
):
    """Scattered and reference power per detector pixel, ``bins`` = (in-plane, across)."""
    tallies, (x, y), (rx, ry) = _trace(
        key, theta_i_deg, theta_s_deg, params, setup, constants, n, estimator, limiting, fold
    )
    half = setup.detector_half_size
    edges = (
        jnp.linspace(-half[0], half[0], bins[0] + 1),
        jnp.linspace(-half[1], half[1], bins[1] + 1),
    )
    scattered, _, _ = jnp.histogram2d(x, y, bins=edges, weights=tallies[:, 2])
    reference, _, _ = jnp.histogram2d(rx, ry, bins=edges, weights=tallies[:, 4])
    return scattered, reference
