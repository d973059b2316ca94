"""Well-conditioned internal coordinates of Eq. (7).

In paper units a2 ~ 1e-11 and a3 ~ 1e-12 while brdf0 ~ 1e-2: a fit or a sampler in those
units is stiff. Internally, angles are scaled by 90° and the coefficients absorb the scale,

    ln BRDF = ln BRDF0 + b1 t x' + (b2 t + b3 t²) x'^α,   t = θi/90°,  x' = (θs − θs0)/90°,

so that b1 = a1·90², b2 = a2·90^(1+α), b3 = a3·90^(2+α) are all O(1) for coatings like the
bundled one. The internal vector is

    z = (ln brdf0, b1, b2, b3, α, θs0/90°).
"""

from __future__ import annotations

import jax.numpy as jnp

from brdf_infer.model.params import Params

ANGLE_SCALE_DEG = 90.0
INTERNAL_NAMES: tuple[str, ...] = ("log_brdf0", "b1", "b2", "b3", "alpha", "t_s0")


def to_internal(params: Params) -> jnp.ndarray:
    """Paper-unit ``Params`` → internal vector z (last axis of length 6)."""
    scale = ANGLE_SCALE_DEG
    alpha = jnp.asarray(params.alpha, float)
    return jnp.stack(
        [
            jnp.log(jnp.asarray(params.brdf0, float)),
            params.a1 * scale**2,
            params.a2 * scale ** (1.0 + alpha),
            params.a3 * scale ** (2.0 + alpha),
            alpha,
            jnp.asarray(params.theta_s0, float) / scale,
        ],
        axis=-1,
    )


def from_internal(z: jnp.ndarray) -> Params:
    """Internal vector z (last axis of length 6) → paper-unit ``Params``."""
    scale = ANGLE_SCALE_DEG
    z = jnp.asarray(z, float)
    alpha = z[..., 4]
    return Params(
        brdf0=jnp.exp(z[..., 0]),
        a1=z[..., 1] / scale**2,
        a2=z[..., 2] * scale ** -(1.0 + alpha),
        a3=z[..., 3] * scale ** -(2.0 + alpha),
        alpha=alpha,
        theta_s0=z[..., 5] * scale,
    )
