"""Credible bands (median, 68 %, 95 %) for the in-plane BRDF, TIS and π·BRDF0 of a
``strumik2024`` run, and for the in-plane BRDF and TIS of a run of any other family.

Every band follows the run's one fold switch, the scene's ``[model] fold`` (default false):
without it the bands are of the physical BRDF, whose TIS is the conservative one for a
stray-light budget; with it Eq. (10)'s folding (a measurement artefact, Sec. 5 of the article)
is in the BRDF and the TIS alike. ``"fold"`` in the bands says which."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer.model import ModelFamily, brdf_inplane, tis
from brdf_infer.params import HemisphereConstants, Params

QUANTILES = {"lo95": 0.025, "lo68": 0.16, "median": 0.5, "hi68": 0.84, "hi95": 0.975}
TIS_THETA_I_DEG = np.arange(0.0, 90.0, 1.0)  # 0°, 1°, …, 89°
BRDF_THETA_S_DEG = np.arange(-90.0, 90.5, 1.0)
# A family's TIS is a 2-D quadrature (≈ 1 ms each): its band is taken over evenly spaced
# draws at every 5° (TIS(70°) included).
FAMILY_TIS_THETA_I_DEG = np.arange(0.0, 90.0, 5.0)
FAMILY_TIS_DRAWS = 400


def quantile_band(samples: np.ndarray, axis: int = 0) -> dict[str, list]:
    """Median and central 68 %/95 % intervals over ``axis`` as nested lists."""
    values = np.quantile(samples, list(QUANTILES.values()), axis=axis)
    return {name: values[k].tolist() for k, name in enumerate(QUANTILES)}


def interval95(values) -> dict[str, float]:
    """Median and central 95 % interval of all values (any shape, flattened)."""
    low, median, high = np.quantile(np.asarray(values, float).reshape(-1), [0.025, 0.5, 0.975])
    return {"median": float(median), "lo95": float(low), "hi95": float(high)}


def draws_params(sites: dict[str, np.ndarray]) -> Params:
    """All draws (chains flattened) of the six parameters, paper units."""
    return Params(*(np.asarray(sites[name]).reshape(-1) for name in Params._fields))


def tis_band(
    params: Params, theta_i_deg, fold: bool, constants: HemisphereConstants
) -> dict[str, list]:
    """TIS(θi) quantiles over all draws, exact 1-D TIS batched over draws × angles."""
    values = np.asarray(tis(np.asarray(theta_i_deg, float), params, fold, constants))
    return {"theta_i_deg": np.asarray(theta_i_deg, float).tolist(), **quantile_band(values)}


def compute_bands(
    params: Params,
    theta_i_deg,
    fold: bool,
    constants: HemisphereConstants,
    with_tis: bool = True,
) -> dict[str, dict]:
    """Every band of a posterior run.

    Args:
        params: parameter draws.
        theta_i_deg: incidence angles of the BRDF bands [deg].
        fold: the scene's ``[model] fold``: Eq. (10) in the BRDF and TIS bands (default
            false, the physical BRDF; the article's Table 3 includes it).
        constants: out-of-plane and folding constants.
        with_tis: compute the TIS band (not when the scene has no out-of-plane model).

    Returns:
        ``{"fold": fold, "tis": …, "brdf_inplane": …, "pi_brdf0": …}`` (no ``"tis"`` without
        ``with_tis``); the BRDF band holds arrays of shape (len(theta_i_deg), 181) over
        θs = −90°…90° [sr⁻¹].
    """
    theta_i = np.asarray(theta_i_deg, float)
    grid_i, grid_s = np.meshgrid(theta_i, BRDF_THETA_S_DEG, indexing="ij")
    batch = Params(*(np.asarray(v)[:, None, None] for v in params))
    brdf = np.asarray(brdf_inplane(grid_i[None], grid_s[None], batch, fold, constants))
    bands = {
        "fold": bool(fold),
        "brdf_inplane": {
            "theta_i_deg": theta_i.tolist(),
            "theta_s_deg": BRDF_THETA_S_DEG.tolist(),
            **quantile_band(brdf),
        },
        "pi_brdf0": quantile_band(np.pi * np.asarray(params.brdf0)),
    }
    if with_tis:
        bands["tis"] = tis_band(params, TIS_THETA_I_DEG, fold, constants)
    return bands


def draws_physical(sites: dict[str, np.ndarray], family: ModelFamily) -> dict[str, np.ndarray]:
    """All draws (chains flattened) of ``family``'s physical parameters."""
    return {name: np.asarray(sites[name]).reshape(-1) for name in family.parameters}


def evenly_spaced(physical: dict[str, np.ndarray], count: int) -> dict[str, np.ndarray]:
    """At most ``count`` evenly spaced draws of every parameter."""
    total = next(iter(physical.values())).size
    if total <= count:
        return physical
    index = np.linspace(0, total - 1, count).round().astype(int)
    return {name: values[index] for name, values in physical.items()}


_PROGRAMS: dict[tuple[str, int], tuple[ModelFamily, object]] = {}


def _program(kind: str, family: ModelFamily, make):
    """``make(family)`` jitted once per family object (a family holds a dict, so it is not
    hashable; keyed by identity, the family kept alive beside its program)."""
    key = (kind, id(family))
    if key not in _PROGRAMS:
        _PROGRAMS[key] = (family, jax.jit(make(family)))
    return _PROGRAMS[key][1]


def _tis_curve_program(family: ModelFamily):
    """TIS of every draw at every angle; the quadrature is mapped over the draws in small
    batches to bound memory."""
    return _program(
        "tis",
        family,
        lambda member: (
            lambda p, theta: jax.lax.map(
                lambda one: jax.vmap(lambda t: member.tis(t, one))(theta), p, batch_size=16
            )
        ),
    )


def _signed_program(family: ModelFamily):
    """The family's in-plane ln BRDF."""
    return _program("signed", family, lambda member: member.log_brdf_signed)


def family_tis_band(
    family: ModelFamily, physical: dict[str, np.ndarray], theta_i_deg, draws: int
) -> dict[str, list]:
    """TIS(θi) quantiles of ``family`` over at most ``draws`` evenly spaced draws."""
    theta = jnp.asarray(theta_i_deg, float)
    thinned = {k: jnp.asarray(v, float) for k, v in evenly_spaced(physical, draws).items()}
    values = np.asarray(_tis_curve_program(family)(thinned, theta))
    return {
        "theta_i_deg": np.asarray(theta_i_deg, float).tolist(),
        "draws": int(values.shape[0]),
        **quantile_band(values),
    }


def family_bands(
    family: ModelFamily, physical: dict[str, np.ndarray], theta_i_deg, with_tis: bool = True
) -> dict[str, dict]:
    """The bands of a run of ``family``: ``{"fold": False, "brdf_inplane": …, "tis": …}`` as
    in :func:`compute_bands` (the TIS at :data:`FAMILY_TIS_THETA_I_DEG` over
    :data:`FAMILY_TIS_DRAWS` draws; no π·BRDF0, a parameter of Eq. 7 only; no Eq. 10 either)."""
    theta_i = np.asarray(theta_i_deg, float)
    grid_i, grid_s = np.meshgrid(theta_i, BRDF_THETA_S_DEG, indexing="ij")
    batch = {k: jnp.asarray(v, float)[:, None, None] for k, v in physical.items()}
    brdf = np.exp(np.asarray(_signed_program(family)(grid_i[None], grid_s[None], batch)))
    bands = {
        "fold": False,
        "brdf_inplane": {
            "theta_i_deg": theta_i.tolist(),
            "theta_s_deg": BRDF_THETA_S_DEG.tolist(),
            **quantile_band(brdf),
        },
    }
    if with_tis:
        bands["tis"] = family_tis_band(family, physical, FAMILY_TIS_THETA_I_DEG, FAMILY_TIS_DRAWS)
    return bands
