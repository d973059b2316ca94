"""Energy conservation: the physical BRDF of Eqs. (7), (8) scatters at most what it receives.

A coating with TIS(θi) > 1 (Eq. 9) at some incidence angle reflects more power than falls on
it. The scene's priors are normals on well-conditioned coordinates (:mod:`brdf_infer.model.priors`)
that know nothing of this: on their own they put about a third of their mass on such
coatings (TIS(70°) > 1 for 33 % of 20,000 draws of the bundled scene's priors). The posterior
model therefore truncates them to

    max over θi ∈ :data:`ENERGY_THETA_I_DEG` of ln TIS(θi) ≤ ln(1 − :data:`ENERGY_MARGIN`),

the physical (unfolded) TIS, whatever the scene's ``[model] fold``: Eq. (10) models what a
detector sees, not what the coating scatters.

The check angles are 0–85° in 5° steps with :data:`ENERGY_NODES` Gauss–Legendre nodes per
panel (not the 64 of :data:`~brdf_infer.model.TIS_NODES`): the check runs at every step of the
sampler, where it costs about 7 µs of a 32 µs value and gradient (2.5° steps with 32 nodes cost
14 µs). TIS(θi) is not monotone in θi for most prior draws (its largest value is at 85° for 39 %
of them), so one angle does not serve. Over 8,000 prior draws of the bundled scene with a
largest check value between 0.5 and 1.2, the TIS on a 0.5° grid with 64 nodes exceeds the
check's largest value by at most 3.4 % (a peak between two check angles, and the coarser
quadrature); the 5 % margin covers that, so an accepted coating has TIS ≤ 0.95 × e^0.034 < 0.99
at every θi in 0–85° (tests/test_answer_records.py checks it on fresh draws). Coatings that
scatter 95–100 % of the light are no black coatings; leaving them out changes no answer here.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer.model._tis import log_tis
from brdf_infer.model.params import PAPER_CONSTANTS, HemisphereConstants, Params

ENERGY_THETA_I_DEG = np.arange(0.0, 85.0 + 1e-9, 5.0)  # [deg], the check angles
ENERGY_NODES = 24  # Gauss–Legendre nodes per panel of the check's TIS
ENERGY_MARGIN = 0.05  # the check's TIS stays ≤ 1 − margin (module docstring)
LOG_TIS_LIMIT = float(np.log1p(-ENERGY_MARGIN))


def max_log_tis(params: Params, constants: HemisphereConstants = PAPER_CONSTANTS) -> jnp.ndarray:
    """The largest ln TIS over the check angles of the physical BRDF (Eqs. 8, 9, no Eq. 10).

    Args:
        params: Eq. (7)'s parameters; fields may be arrays of one batch shape.
        constants: Δφ and folding constants of Eq. (8).

    Returns:
        max ln TIS [-], of the batch shape.
    """
    values = log_tis(jnp.asarray(ENERGY_THETA_I_DEG), params, False, constants, ENERGY_NODES)
    return jnp.max(values, axis=-1)


def conserves_energy(
    params: Params, constants: HemisphereConstants = PAPER_CONSTANTS
) -> jnp.ndarray:
    """True where the coating scatters at most what it receives (module docstring)."""
    return max_log_tis(params, constants) <= LOG_TIS_LIMIT


def energy_log_factor(
    params: Params, constants: HemisphereConstants = PAPER_CONSTANTS
) -> jnp.ndarray:
    """0 where :func:`conserves_energy`, −∞ elsewhere: the truncation as a log density.

    The indicator does not depend smoothly on the parameters, so no gradient flows through it
    (``stop_gradient``): inside the allowed region the density is the scene's prior, and a
    sampler's step that leaves it is rejected.
    """
    frozen = jax.tree_util.tree_map(jax.lax.stop_gradient, params)
    return jnp.where(conserves_energy(frozen, constants), 0.0, -jnp.inf)
