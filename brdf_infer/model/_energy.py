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

How the sampler meets the boundary. Eq. (7) multiplies both branches of Eq. (8) by BRDF0, so
every TIS(θi) of Eq. (9) is proportional to it and the check bounds ln BRDF0 given the other
five parameters: ln BRDF0 ≤ :func:`log_brdf0_bound` = ln(1 − margin) − max ln TIS|BRDF0=1
[ln sr⁻¹]. Where the posterior model samples whitened coefficients with ln BRDF0 free
(:mod:`brdf_infer.posterior._model`: every scene that does not fix BRDF0), the whitening's ln
BRDF0, x, is mapped below that bound (less :data:`BOUND_GAP`, for rounding) by
:func:`below_bound`, y = bound − s·softplus((bound − x)/s), a smooth increasing bijection of
the real line onto (−∞, bound), and the map's log-Jacobian joins the whitening's. Every point
the sampler reaches is then a coating the check keeps; the density of the parameters is
exactly the scene's priors truncated at the boundary times the likelihood (a change of
variables: nothing reshapes the prior, and simulations draw the same one by rejection,
:func:`brdf_infer.posterior.prior_draws`); and a NUTS trajectory has no wall to end on: past
the bound, x meets a density that falls as e^(−(x − bound)/s). The scale s is
:data:`ENERGY_MAP_SOFTNESS` (1) times the regression's sd of ln BRDF0 given b1–b3, one unit
of the whitened coordinate (0.048–0.127 on the bundled rows for a sample scale of 0.01–0.3;
as the data say less it tends to the prior's sd, 2). Below the bound y is x to within
s·e^(−(bound − x)/s): over the 4000 draws of the bundled posterior in the test suite the map
moved ln BRDF0 by at most 3.8e-12 and its log-Jacobian was −3.7e-11 at most.

Measured on a shared 2-core machine. The 20-row one-sample single-series scene
(:data:`brdf_infer.studies.synthetic.GEOMETRIES`, data simulated at the UV parameters), NUTS 4 ×
(1000 + 1000), seeds 0–15: 3 divergent transitions in all with the map, 23 with the hard
boundary before it (14 on seed 15, whose posterior reaches TIS 0.9), 2 without the physical
prior; a fixed s = 0.1 or 1 gave 5 and 4, a smooth barrier in place of the hard factor 15 and
14 (of width 1 and 2 in ln TIS: the sampler's steps near the boundary change ln TIS by up to
1.3, more than such a barrier can absorb without touching black coatings' TIS). SBC of
``lya``, 200 replicates, seed 0: 8 replicates with a divergent transition with the map, 17
with the hard boundary (fixed s = 0.1 and 1: 9 and 13). NUTS on the prior alone (the
likelihood hidden; a third of the untruncated mass lies past the boundary): 48 divergent
transitions in 8000 iterations with the map, 2612 with the hard boundary, 465, 49 and 26 with
a fixed s = 0.1, 1 and 3, none untruncated. The bound's maximum over the check angles has kinks
where the largest angle changes; a smooth maximum (log-sum-exp, sharpness 10) left the last
count about as it was (38 at s = 1), and the hard maximum is kept: the truncation stays the
check's. The map adds the check's gradient to every step: value and gradient on the bundled
rows, in a compiled loop, 160–200 µs against 125–148 µs with the hard factor and 94–107 µs
without the physical prior (two runs each, the machine shared).

Where ln BRDF0 is fixed, or not whitened (``reparametrise=False``), the truncation stays a
factor of the model, 0 where :func:`conserves_energy` and −∞ beyond, with no gradient
(:func:`energy_log_factor`): a trajectory that reaches it ends there, a divergent transition.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer.model._tis import log_tis, log_tis_at
from brdf_infer.model.params import PAPER_CONSTANTS, HemisphereConstants, Params

ENERGY_THETA_I_DEG = np.arange(0.0, 85.0 + 1e-9, 5.0)  # [deg], the check angles
ENERGY_NODES = 24  # Gauss–Legendre nodes per panel of the check's TIS
ENERGY_MARGIN = 0.05  # the check's TIS stays ≤ 1 − margin (module docstring)
LOG_TIS_LIMIT = float(np.log1p(-ENERGY_MARGIN))
# [-]: the map's scale s in sds of ln BRDF0 given the other coefficients (module docstring)
ENERGY_MAP_SOFTNESS = 1.0
# [ln sr⁻¹]: the sampler's bound lies this far inside log_brdf0_bound's, so that no rounding of
# ln BRDF0 (ln of its exponential) or of the check puts a draw beyond conserves_energy
BOUND_GAP = 1e-12


def max_log_tis(params: Params, constants: HemisphereConstants = PAPER_CONSTANTS) -> jnp.ndarray:
    """The largest ln TIS over the check angles of the physical BRDF (Eqs. 8, 9, no Eq. 10).

    The largest angle is found with the gradient stopped and ln TIS evaluated again there,
    with the same arithmetic: the value is the maximum's and so is the gradient (the
    maximum's derivative is that of its largest term), while the reverse pass runs through
    one angle instead of all 18. Value and gradient of the bundled posterior in a compiled
    loop: 150–159 µs before, 117–128 µs after (2 cores, runs alternated).

    Args:
        params: Eq. (7)'s parameters; fields may be arrays of one batch shape.
        constants: Δφ and folding constants of Eq. (8).

    Returns:
        max ln TIS [-], of the batch shape.
    """
    angles = jnp.asarray(ENERGY_THETA_I_DEG)
    frozen_params, frozen_constants = jax.tree_util.tree_map(
        jax.lax.stop_gradient, (params, constants)
    )
    values = log_tis(angles, frozen_params, False, frozen_constants, ENERGY_NODES)
    largest = angles[jnp.argmax(values, axis=-1)]  # [deg], of the batch shape
    return log_tis_at(largest, params, False, constants, ENERGY_NODES)


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


def log_brdf0_bound(
    params: Params, constants: HemisphereConstants = PAPER_CONSTANTS
) -> jnp.ndarray:
    """The largest ln BRDF0 [ln sr⁻¹] that :func:`conserves_energy` allows with the other five
    parameters of ``params`` (its ``brdf0`` is not used).

    Eq. (7) scales both branches of Eq. (8) by BRDF0, so the TIS of Eq. (9) is proportional to
    it: max ln TIS = ln BRDF0 + max ln TIS|BRDF0=1, and a coating conserves energy exactly when
    ln BRDF0 ≤ :data:`LOG_TIS_LIMIT` − max ln TIS|BRDF0=1, the value returned.
    """
    unit = params._replace(brdf0=jnp.ones_like(jnp.asarray(params.brdf0, float)))
    return LOG_TIS_LIMIT - max_log_tis(unit, constants)


def below_bound(
    coordinate: jnp.ndarray, bound: jnp.ndarray, scale: jnp.ndarray
) -> tuple[jnp.ndarray, jnp.ndarray]:
    """y = bound − s·softplus((bound − x)/s) and ln dy/dx = −softplus((x − bound)/s) [-], for
    the sampler's coordinate x, the bound and the scale s > 0 in the units of ln BRDF0.

    A smooth increasing bijection of the real line onto (−∞, bound): y = x − s·ln(1 +
    e^(−(bound − x)/s)) is x to within s·e^(−(bound − x)/s) below the bound, and approaches
    the bound as e^(−(x − bound)/s) above it, where the log-slope falls linearly. Finite, with
    finite gradients, for every finite input.
    """
    distance = (bound - coordinate) / scale
    return bound - scale * jax.nn.softplus(distance), -jax.nn.softplus(-distance)
