"""Credible bands (median, 68 %, 95 %) for the in-plane BRDF and the TIS of a run of any
model family, and π·BRDF0 for Eq. (7)'s.

Every band follows the run's one fold switch, the scene's ``[model] fold`` (default false):
without it the bands are of the physical BRDF, whose TIS is the conservative one for a
stray-light budget; with it Eq. (10)'s folding (a measurement artefact, Sec. 5 of the article)
is in the BRDF and the TIS alike. ``"fold"`` in the bands says which."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer._internal.stored_programs import StoredFunction
from brdf_infer.model import ModelFamily
from brdf_infer.model.params import Params
from brdf_infer.runs.records import Bands

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


def draws_physical(sites: dict[str, np.ndarray], family: ModelFamily) -> dict[str, np.ndarray]:
    """All draws (chains flattened) of ``family``'s physical parameters."""
    return {name: np.asarray(sites[name]).reshape(-1) for name in family.parameters}


def evenly_spaced(physical: dict[str, np.ndarray], count: int) -> dict[str, np.ndarray]:
    """At most ``count`` evenly spaced draws (the leading axis) of every parameter."""
    total = len(next(iter(physical.values())))
    if total <= count:
        return physical
    index = np.linspace(0, total - 1, count).round().astype(int)
    return {name: values[index] for name, values in physical.items()}


def _program(kind: str, family: ModelFamily, make):
    """``make(family)`` jitted once per family object and kept on it (``_programs``; a family
    holds a dict, so it cannot key a cache): the programs go when the family goes, so runs
    repeated in one process hold flat memory."""
    programs = family.__dict__.setdefault("_programs", {})
    if kind not in programs:
        fields = [(f.name, getattr(family, f.name)) for f in dataclasses.fields(family)]
        constants = [(name, value) for name, value in fields if not callable(value)]
        programs[kind] = StoredFunction(make(family), ("bands " + kind, constants))
    return programs[kind]


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


def _inplane_program(family: ModelFamily):
    """The family's closed-form in-plane BRDF [sr⁻¹] (one program: op by op, each operation
    is a program of its own)."""
    return _program(
        "inplane", family, lambda member: lambda i, s, p: jnp.exp(member.log_brdf_inplane(i, s, p))
    )


def tis_band(
    family: ModelFamily, physical: dict[str, np.ndarray], theta_i_deg, draws: int
) -> dict[str, list]:
    """TIS(θi) quantiles of ``family``: over every draw where its TIS is Eq. (9) batched (one
    call), else over at most ``draws`` evenly spaced draws (``"draws"``: how many)."""
    theta = np.asarray(theta_i_deg, float)
    if family.log_tis_draws is not None:
        values = np.asarray(jnp.exp(family.log_tis_draws(theta, physical)))
        return {"theta_i_deg": theta.tolist(), **quantile_band(values)}
    values = tis_curve_draws(family, evenly_spaced(physical, draws), theta)
    return {"theta_i_deg": theta.tolist(), "draws": int(values.shape[0]), **quantile_band(values)}


def tis_curve_draws(family: ModelFamily, physical: dict[str, np.ndarray], theta_i_deg):
    """TIS of every draw of ``physical`` at every θi (draws, angles) by the family's own TIS
    (a quadrature), in one compiled program."""
    batch = {k: jnp.asarray(v, float) for k, v in physical.items()}
    return np.asarray(_tis_curve_program(family)(batch, jnp.asarray(theta_i_deg, float)))


def _brdf_inplane_draws(family: ModelFamily, physical: dict[str, np.ndarray], grid_i, grid_s):
    """The in-plane BRDF of every draw on the grid [sr⁻¹]: the family's closed form directly
    where it has one (Eq. 7), else its compiled hemisphere BRDF at φ = 180° or 0°."""
    if family.log_brdf_inplane is not None:
        batch = {k: np.asarray(v)[:, None, None] for k, v in physical.items()}
        return np.asarray(_inplane_program(family)(grid_i[None], grid_s[None], batch))
    batch = {k: jnp.asarray(v, float)[:, None, None] for k, v in physical.items()}
    return np.exp(np.asarray(_signed_program(family)(grid_i[None], grid_s[None], batch)))


def posterior_bands(
    family: ModelFamily, physical: dict[str, np.ndarray], theta_i_deg, with_tis: bool = True
) -> Bands:
    """Every band of a posterior run of ``family``.

    Args:
        family: the run's family (its ``fold``: the scene's ``[model] fold``, Eq. 10 in the
            BRDF and TIS bands; default false, the physical BRDF; the article's Table 3
            includes it).
        physical: every draw of its physical parameters.
        theta_i_deg: incidence angles of the BRDF bands [deg].
        with_tis: compute the TIS band (not when the scene has no out-of-plane model).

    Returns:
        ``{"fold": …, "brdf_inplane": …, "pi_brdf0": …, "tis": …}``: the BRDF band holds arrays
        of shape (len(theta_i_deg), 181) over θs = −90°…90° [sr⁻¹]; π·BRDF0 for Eq. (7)'s
        family only; the TIS at every 1° over every draw for Eq. (9), else at every 5°
        (:data:`FAMILY_TIS_THETA_I_DEG`) over :data:`FAMILY_TIS_DRAWS` draws; no ``"tis"``
        without ``with_tis``.
    """
    theta_i = np.asarray(theta_i_deg, float)
    grid_i, grid_s = np.meshgrid(theta_i, BRDF_THETA_S_DEG, indexing="ij")
    bands = {
        "fold": bool(family.fold),
        "brdf_inplane": {
            "theta_i_deg": theta_i.tolist(),
            "theta_s_deg": BRDF_THETA_S_DEG.tolist(),
            **quantile_band(_brdf_inplane_draws(family, physical, grid_i, grid_s)),
        },
    }
    if family.paper_parameters:
        bands["pi_brdf0"] = quantile_band(np.pi * np.asarray(physical["brdf0"]))
    if with_tis:
        exact = family.log_tis_draws is not None
        angles = TIS_THETA_I_DEG if exact else FAMILY_TIS_THETA_I_DEG
        bands["tis"] = tis_band(family, physical, angles, FAMILY_TIS_DRAWS)
    return bands
