"""Credible bands (median, 68 %, 95 %) for the in-plane BRDF, TIS and π·BRDF0."""

from __future__ import annotations

import numpy as np

from brdf_infer.model import brdf_inplane, tis
from brdf_infer.params import HemisphereConstants, Params

QUANTILES = {"lo95": 0.025, "lo68": 0.16, "median": 0.5, "hi68": 0.84, "hi95": 0.975}
TIS_THETA_I_DEG = np.arange(0.0, 90.0, 1.0)  # 0°, 1°, …, 89°
BRDF_THETA_S_DEG = np.arange(-90.0, 90.5, 1.0)


def quantile_band(samples: np.ndarray, axis: int = 0) -> dict[str, list]:
    """Median and central 68 %/95 % intervals over ``axis`` as nested lists."""
    values = np.quantile(samples, list(QUANTILES.values()), axis=axis)
    return {name: values[k].tolist() for k, name in enumerate(QUANTILES)}


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
        fold: the scene's in-plane model includes Eq. (10) (the BRDF bands follow it; the TIS
            always includes the folding, as the paper's Eq. (9) and Table 3 do).
        constants: out-of-plane and folding constants.
        with_tis: compute the TIS band (not when the scene has no out-of-plane model).

    Returns:
        ``{"tis": …, "brdf_inplane": …, "pi_brdf0": …}`` (no ``"tis"`` without ``with_tis``);
        the BRDF band holds arrays of shape (len(theta_i_deg), 181) over θs = −90°…90° [sr⁻¹].
    """
    theta_i = np.asarray(theta_i_deg, float)
    grid_i, grid_s = np.meshgrid(theta_i, BRDF_THETA_S_DEG, indexing="ij")
    batch = Params(*(np.asarray(v)[:, None, None] for v in params))
    brdf = np.asarray(brdf_inplane(grid_i[None], grid_s[None], batch, fold, constants))
    bands = {
        "brdf_inplane": {
            "theta_i_deg": theta_i.tolist(),
            "theta_s_deg": BRDF_THETA_S_DEG.tolist(),
            **quantile_band(brdf),
        },
        "pi_brdf0": quantile_band(np.pi * np.asarray(params.brdf0)),
    }
    if with_tis:
        bands["tis"] = tis_band(params, TIS_THETA_I_DEG, True, constants)
    return bands
