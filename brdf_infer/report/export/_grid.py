"""The scatter grid of a tabular BSDF: directions in the specular frame, tables and their
hemisphere integral.

Directions in the format's specular frame (ψ, r) map to the model's (θ, φ) as
:mod:`brdf_infer.tables.bsdf_file` describes.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer.model import log_brdf_hemisphere
from brdf_infer.model.params import HemisphereConstants, Params
from brdf_infer.tables.bsdf_file import scattered_direction, specular_frame_to_model

DEFAULT_THETA_I_DEG = np.arange(0.0, 86.0, 5.0)  # 0°, 5°, …, 85°
DEFAULT_AZIMUTH_STEP_DEG = 5.0
DEFAULT_RADIAL_STEP_DEG = 1.0


@dataclass(frozen=True)
class ScatterGrid:
    """Angles of a plane-symmetric tabular BSDF [deg].

    Attributes:
        theta_i_deg: angles of incidence (of the specular ray), shape (n_aoi,).
        azimuth_deg: scatter azimuths ψ from 0° to 180°, shape (n_azimuth,).
        radial_deg: scatter radials r from 0° to min(180°, 90° + max AOI), shape (n_radial,).
    """

    theta_i_deg: np.ndarray
    azimuth_deg: np.ndarray
    radial_deg: np.ndarray


def _steps_to(stop: float, step: float) -> np.ndarray:
    """0, step, 2·step, … with ``stop`` as the last value (the last step may be shorter)."""
    count = int(np.floor(stop / step + 1e-9))
    values = step * np.arange(count + 1)
    return values if np.isclose(values[-1], stop) else np.append(values, stop)


def scatter_grid(
    theta_i_deg=DEFAULT_THETA_I_DEG,
    azimuth_step_deg: float = DEFAULT_AZIMUTH_STEP_DEG,
    radial_step_deg: float = DEFAULT_RADIAL_STEP_DEG,
) -> ScatterGrid:
    """The grid covering the whole hemisphere at every angle of incidence.

    Radials reach min(180°, 90° + max θi), the backward horizon of the most oblique
    incidence; below the horizon a table holds 0.
    """
    theta_i = np.sort(np.asarray(theta_i_deg, float).reshape(-1))
    radial_stop = min(180.0, 90.0 + float(theta_i.max()))
    return ScatterGrid(
        theta_i_deg=theta_i,
        azimuth_deg=_steps_to(180.0, azimuth_step_deg),
        radial_deg=_steps_to(radial_stop, radial_step_deg),
    )


@partial(jax.jit, static_argnames=("fold",))
def brdf_table(
    theta_i_deg: float,
    azimuth_deg: jnp.ndarray,
    radial_deg: jnp.ndarray,
    params: Params,
    fold: bool,
    constants: HemisphereConstants,
) -> jnp.ndarray:
    """BRDF [sr⁻¹] of Eqs. (7), (8), (10) on the (azimuth, radial) grid of one θi.

    Args:
        theta_i_deg: angle of incidence [deg].
        azimuth_deg, radial_deg: the grid's azimuths ψ and radials r [deg].
        params: parameters; fields may carry a leading batch axis (draws).
        fold: include the folding term of Eq. (10).
        constants: Δφ and folding constants.

    Returns:
        Shape ``batch_shape + (n_azimuth, n_radial)``; 0 below the horizon.
    """
    psi, r = jnp.meshgrid(azimuth_deg, radial_deg, indexing="ij")
    theta, phi, z = specular_frame_to_model(theta_i_deg, psi, r)
    batch = Params(*(jnp.asarray(v, float)[..., None, None] for v in params))
    log_value = log_brdf_hemisphere(theta_i_deg, theta, phi, batch, fold, constants)
    return jnp.where(z > 0.0, jnp.exp(log_value), 0.0)


def table_integral(
    theta_i_deg: float, azimuth_deg: np.ndarray, radial_deg: np.ndarray, table: np.ndarray
) -> np.ndarray:
    """∫ BSDF cos θ dΩ of a plane-symmetric table (Eq. 9 on the table's own grid).

    dΩ = sin r dr dψ in the specular frame; trapezoid rule in ψ ∈ [0°, 180°] (doubled for
    the mirror half) and in r. Below the horizon cos θ·BSDF is 0, and it goes to 0
    continuously at the horizon, so the rule converges as (step)².

    Args:
        theta_i_deg: angle of incidence [deg].
        azimuth_deg, radial_deg: grid [deg].
        table: BSDF [sr⁻¹], shape ``(..., n_azimuth, n_radial)``.

    Returns:
        The integral, shape ``table.shape[:-2]``.
    """
    psi, r = np.meshgrid(azimuth_deg, radial_deg, indexing="ij")
    _, _, z = (np.asarray(c) for c in scattered_direction(theta_i_deg, psi, r))
    integrand = np.asarray(table) * np.clip(z, 0.0, None) * np.sin(np.radians(r))
    over_radial = np.trapezoid(integrand, np.radians(radial_deg), axis=-1)
    return 2.0 * np.trapezoid(over_radial, np.radians(azimuth_deg), axis=-1)
