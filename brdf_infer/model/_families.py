"""Model families behind one interface: ln BRDF over the hemisphere, TIS, parameters, priors.

A family is a BRDF written for one point (θi, θ, φ) in the paper's frame (forward-scattering
plane at φ = 180°, Sec. 4.1) and evaluated on arrays by broadcasting; its parameters are
sampled in internal coordinates (well conditioned, unbounded or simply bounded) under default
priors, and mapped to the physical parameters in the units the ray tracers use.

* ``strumik2024``: Eqs. (7), (8), (10); its parameters are Eq. (7)'s
  (:attr:`ModelFamily.paper_parameters`): its posterior samples the scene's ``[priors]`` in
  whitened coordinates (:mod:`brdf_infer.posterior`), its TIS is Eq. (9) batched.
* ``abg``: A / (B + ρ^g), ρ = |β − β₀| (Harvey 1976), sampled as ln(A/B) (the BRDF at the
  specular direction), ln ρ_k = ln(B)/g (the knee) and g.
* ``harvey-shack``: b₀ [1 + (ρ/L)²]^(S/2), sampled as ln b₀, ln L and S.
* ``lambertian``: TIS/π, sampled as ln TIS.
* ``lambertian+abg``: a diffuse floor ρ_d/π plus an ABg lobe.

TIS: exact for ``lambertian``; by the unit-disk quadrature of :mod:`brdf_infer.model._lobes`
for the lobes (its ``fit`` node counts: relative error < 1e-9 against adaptive
quadrature in the benchmark, ≈ 1 ms per TIS); Eq. (9) for ``strumik2024``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer._internal.units import DEG
from brdf_infer.errors import BadInputError
from brdf_infer.model._hemisphere import log_brdf_hemisphere
from brdf_infer.model._inplane import log_brdf_inplane
from brdf_infer.model._lobes import (
    FIT_QUADRATURE,
    abg_integral,
    abg_log_bsdf,
    beta_distance,
    harvey_shack_integral,
    harvey_shack_log_bsdf,
)
from brdf_infer.model._tis import log_tis
from brdf_infer.model.params import (
    DPHI_NAME,
    PAPER_CONSTANTS,
    PARAM_NAMES,
    HemisphereConstants,
    Params,
    with_dphi_scale,
)
from brdf_infer.model.priors import Prior

Physical = dict[str, jnp.ndarray]


@dataclass(frozen=True)
class Coordinate:
    """One internal coordinate: its sample site and default prior (on the coordinate)."""

    site: str
    prior: Prior
    description: str


@dataclass(frozen=True)
class ModelFamily:
    """A BRDF family (module docstring).

    Attributes:
        name: the family's name (``[model] family``, ``--model``).
        parameters: physical parameter names, in order.
        units: each parameter's unit.
        coordinates: the internal coordinates, in order.
        to_physical: internal coordinates (dict by site) → physical parameters.
        log_brdf: ln BRDF(θi, θ, φ; physical) [ln sr⁻¹], angles in degrees, broadcasting.
        tis: TIS(θi; physical) [-] for one scalar θi and scalar parameters.
        exact_tis: the TIS is closed-form (else a quadrature).
        title: how a figure names the model.
        as_params: the physical parameters as Eq. (7)'s six (:class:`Params`); only
            ``strumik2024`` has them (:attr:`paper_parameters`).
        fold: Eq. (10)'s folding is in the BRDF (``strumik2024`` with the scene's switch).
        constants: Eq. (8)'s Δφ and Eq. (10)'s folding constants (``strumik2024``).
        log_brdf_inplane: ln BRDF in the plane of incidence at a signed θs in closed form
            (Eq. 7); None: the hemisphere's BRDF at φ = 180° (forward) or 0°.
        log_tis_draws: ln TIS(θi) of every draw at every θi in one call, (draws, angles)
            (Eq. 9 batched); None: :attr:`tis` per draw, a quadrature, over thinned draws.
        dphi_free: ``strumik2024`` with Eq. (8)'s out-of-plane width a parameter,
            ``dphi_scale`` (the factor on the constants' Δφ), among its physical parameters.
        amplitudes: the parameters the BRDF is proportional to, jointly: multiplying each of
            them by f multiplies the BRDF everywhere, and so the TIS, by f (Eq. 7's BRDF0;
            ABg's A; a sum of lobes: every lobe's). A sample effect u (a shift of every ln R
            of one physical sample) is the factor f = eᵘ (:meth:`scaled`).
    """

    name: str
    parameters: tuple[str, ...]
    units: dict[str, str]
    coordinates: tuple[Coordinate, ...]
    to_physical: Callable[[dict], Physical]
    log_brdf: Callable[..., jnp.ndarray]
    tis: Callable[..., jnp.ndarray]
    exact_tis: bool
    title: str = ""
    as_params: Callable[[Physical], Params] | None = None
    fold: bool = False
    constants: HemisphereConstants = PAPER_CONSTANTS
    log_brdf_inplane: Callable[..., jnp.ndarray] | None = None
    log_tis_draws: Callable[..., jnp.ndarray] | None = None
    dphi_free: bool = False
    amplitudes: tuple[str, ...] = ()

    def scaled(self, physical: Physical, log_factor) -> Physical:
        """The parameters of the BRDF ``physical`` times e^``log_factor`` (broadcast against
        the draws): every :attr:`amplitudes` parameter times that factor, the rest unchanged."""
        factor = np.exp(np.asarray(log_factor, float))
        return {
            name: np.asarray(values) * factor if name in self.amplitudes else values
            for name, values in physical.items()
        }

    @property
    def paper_parameters(self) -> bool:
        """The family's parameters are Eq. (7)'s six: the paper's regression, the whitened
        posterior under the scene's ``[priors]`` (:mod:`brdf_infer.posterior`), π·BRDF0 and
        the studies written for Eq. (7) (instrument kernels, ray tracing, sensitivity, where
        to measure next) apply to it."""
        return self.as_params is not None

    @property
    def abg_parameters(self) -> bool:
        """The family's parameters are ABg's A, B, g (Harvey 1976) and nothing else, so an
        ABg export reads them from its posterior instead of fitting them."""
        return set(self.parameters) == {"A", "B", "g"}

    def hemispheric(self, out_of_plane: bool) -> bool:
        """The family predicts the BRDF over the hemisphere (TIS bands, maps): Eq. (7)'s with
        Eq. (8) only, the scene's ``[model] out_of_plane``; every other family always."""
        return out_of_plane or not self.paper_parameters

    def with_fold(self, fold: bool) -> ModelFamily:
        """The same family with Eq. (10)'s folding on or off.

        Raises:
            ValueError: ``fold`` for a family without Eq. (10).
        """
        if self.paper_parameters:
            return strumik_family(fold, self.constants, self.dphi_free)
        if fold:
            raise ValueError(f"{self.name} has no Eq. (10) folding")
        return self

    def constants_of(self, physical: Physical) -> HemisphereConstants:
        """Eq. (8)'s constants of the draws ``physical`` (:func:`draw_constants`)."""
        return draw_constants(self.constants, self.dphi_free, physical)

    def log_brdf_signed(self, theta_i_deg, theta_s_deg, physical: Physical) -> jnp.ndarray:
        """ln BRDF in the plane of incidence at a signed θs (forward > 0, Sec. 4.1)."""
        if self.log_brdf_inplane is not None:
            return self.log_brdf_inplane(theta_i_deg, theta_s_deg, physical)
        theta_s = jnp.asarray(theta_s_deg, float)
        phi = jnp.where(theta_s >= 0.0, 180.0, 0.0)
        return self.log_brdf(theta_i_deg, jnp.abs(theta_s), phi, physical)

    def log_brdf_rows(self, theta_i_deg, theta_s_deg, physical: Physical, phi_s_deg=None):
        """ln BRDF of measurement rows: in-plane at a signed θs, out of the plane (finite
        ``phi_s_deg``) at the polar angle θs and azimuth φs."""
        in_plane = self.log_brdf_signed(theta_i_deg, theta_s_deg, physical)
        if phi_s_deg is None:
            return in_plane
        outside = jnp.isfinite(phi_s_deg)
        phi = jnp.where(outside, phi_s_deg, 180.0)
        return jnp.where(outside, self.log_brdf(theta_i_deg, theta_s_deg, phi, physical), in_plane)

    def tis_curve(self, theta_i_deg, physical: Physical) -> jnp.ndarray:
        """TIS at every θi of a 1-D array, for every draw of the parameters' leading axis."""
        theta = jnp.asarray(theta_i_deg, float)
        per_draw = jax.vmap(lambda p: jax.vmap(lambda t: self.tis(t, p))(theta))
        return per_draw({k: jnp.atleast_1d(jnp.asarray(v, float)) for k, v in physical.items()})


def _rho(theta_i_deg, theta_deg, phi_deg):
    return beta_distance(theta_i_deg, theta_deg, phi_deg)


# ------------------------------------------------------------------------------------ ABg


def _abg_physical(z: dict) -> Physical:
    g = z["g"]
    log_b = g * z["log_knee"]
    return {"A": jnp.exp(z["log_peak"] + log_b), "B": jnp.exp(log_b), "g": g}


def _abg_log_brdf(theta_i_deg, theta_deg, phi_deg, p: Physical):
    return abg_log_bsdf(
        jnp.log(p["A"]), jnp.log(p["B"]), p["g"], _rho(theta_i_deg, theta_deg, phi_deg)
    )


def _abg_tis(theta_i_deg, p: Physical):
    sin_theta_i = jnp.sin(theta_i_deg * DEG)
    return p["A"] * abg_integral(jnp.log(p["B"]), p["g"], sin_theta_i, FIT_QUADRATURE)


_ABG_COORDINATES = (
    Coordinate(
        "log_peak", Prior("normal", loc=0.0, scale=5.0), "ln(A/B), the BRDF at specular [ln sr⁻¹]"
    ),
    Coordinate(
        "log_knee", Prior("normal", loc=-3.0, scale=3.0), "ln ρ_k = ln(B)/g, where the lobe bends"
    ),
    Coordinate("g", Prior("uniform", lower=0.05, upper=6.0), "g, the power of the lobe's tail"),
)

# --------------------------------------------------------------------------- Harvey–Shack


def _hs_physical(z: dict) -> Physical:
    return {"b0": jnp.exp(z["log_b0"]), "L": jnp.exp(z["log_l"]), "S": z["S"]}


def _hs_log_brdf(theta_i_deg, theta_deg, phi_deg, p: Physical):
    rho = _rho(theta_i_deg, theta_deg, phi_deg)
    return harvey_shack_log_bsdf(jnp.log(p["b0"]), jnp.log(p["L"]), p["S"], rho)


def _hs_tis(theta_i_deg, p: Physical):
    sin_theta_i = jnp.sin(theta_i_deg * DEG)
    return p["b0"] * harvey_shack_integral(jnp.log(p["L"]), p["S"], sin_theta_i, FIT_QUADRATURE)


_HS_COORDINATES = (
    Coordinate(
        "log_b0", Prior("normal", loc=0.0, scale=5.0), "ln b₀, the BRDF at specular [ln sr⁻¹]"
    ),
    Coordinate("log_l", Prior("normal", loc=-3.0, scale=3.0), "ln L, the shoulder in |β − β₀|"),
    Coordinate("S", Prior("uniform", lower=-8.0, upper=0.0), "S, the slope of the tail in log–log"),
)

# ----------------------------------------------------------------------------- Lambertian


def _lambert_physical(z: dict) -> Physical:
    return {"tis": jnp.exp(z["log_tis"])}


def _lambert_log_brdf(theta_i_deg, theta_deg, phi_deg, p: Physical):
    shape = jnp.broadcast_shapes(
        jnp.shape(theta_i_deg), jnp.shape(theta_deg), jnp.shape(phi_deg), jnp.shape(p["tis"])
    )
    return jnp.broadcast_to(jnp.log(p["tis"] / jnp.pi), shape)


def _lambert_tis(theta_i_deg, p: Physical):
    return p["tis"] + 0.0 * theta_i_deg


_LAMBERT_COORDINATES = (
    Coordinate(
        "log_tis",
        Prior("truncated_normal", loc=-4.6, scale=3.0, upper=0.0),
        "ln TIS (TIS ≤ 1), the BRDF is TIS/π",
    ),
)

# ------------------------------------------------------------------------ Lambertian + ABg


def _lambert_abg_physical(z: dict) -> Physical:
    return {"rho_d": jnp.exp(z["log_rho_d"]), **_abg_physical(z)}


def _lambert_abg_log_brdf(theta_i_deg, theta_deg, phi_deg, p: Physical):
    lobe = _abg_log_brdf(theta_i_deg, theta_deg, phi_deg, p)
    return jnp.logaddexp(jnp.log(p["rho_d"] / jnp.pi), lobe)


def _lambert_abg_tis(theta_i_deg, p: Physical):
    return p["rho_d"] + _abg_tis(theta_i_deg, p)


_LAMBERT_ABG_COORDINATES = (
    Coordinate(
        "log_rho_d",
        Prior("truncated_normal", loc=-6.0, scale=3.0, upper=0.0),
        "ln ρ_d, the diffuse reflectance (floor ρ_d/π)",
    ),
    *_ABG_COORDINATES,
)


FAMILIES: dict[str, ModelFamily] = {
    "abg": ModelFamily(
        "abg",
        ("A", "B", "g"),
        {"A": "sr⁻¹", "B": "-", "g": "-"},
        _ABG_COORDINATES,
        _abg_physical,
        _abg_log_brdf,
        _abg_tis,
        exact_tis=False,
        title="abg",
        amplitudes=("A",),
    ),
    "harvey-shack": ModelFamily(
        "harvey-shack",
        ("b0", "L", "S"),
        {"b0": "sr⁻¹", "L": "-", "S": "-"},
        _HS_COORDINATES,
        _hs_physical,
        _hs_log_brdf,
        _hs_tis,
        exact_tis=False,
        title="harvey-shack",
        amplitudes=("b0",),
    ),
    "lambertian": ModelFamily(
        "lambertian",
        ("tis",),
        {"tis": "-"},
        _LAMBERT_COORDINATES,
        _lambert_physical,
        _lambert_log_brdf,
        _lambert_tis,
        exact_tis=True,
        title="lambertian",
        amplitudes=("tis",),
    ),
    "lambertian+abg": ModelFamily(
        "lambertian+abg",
        ("rho_d", "A", "B", "g"),
        {"rho_d": "-", "A": "sr⁻¹", "B": "-", "g": "-"},
        _LAMBERT_ABG_COORDINATES,
        _lambert_abg_physical,
        _lambert_abg_log_brdf,
        _lambert_abg_tis,
        exact_tis=False,
        title="lambertian+abg",
        amplitudes=("rho_d", "A"),
    ),
}
REFERENCE_FAMILY = "strumik2024"
FAMILY_NAMES: tuple[str, ...] = (REFERENCE_FAMILY, *FAMILIES)


def draw_constants(
    constants: HemisphereConstants, dphi_free: bool, physical: Physical
) -> HemisphereConstants:
    """The constants of Eq. (8) for the draws ``physical``: with ``dphi_free`` their Δφ times
    each draw's ``dphi_scale`` (:func:`~brdf_infer.model.params.with_dphi_scale`), else
    ``constants``."""
    if dphi_free:
        return with_dphi_scale(constants, jnp.asarray(physical[DPHI_NAME], float))
    return constants


def strumik_family(
    fold: bool = False,
    constants: HemisphereConstants = PAPER_CONSTANTS,
    dphi_free: bool = False,
) -> ModelFamily:
    """``strumik2024``: Eqs. (7), (8) (and (10) when ``fold``, the scene's switch) with the
    scene's constants; with ``dphi_free`` Eq. (8)'s out-of-plane width is a seventh physical
    parameter, ``dphi_scale``, the factor on the constants' Δφ = c1·θi + c2 (one value per
    draw, :func:`~brdf_infer.model.params.with_dphi_scale`).

    Its coordinates are empty: its posterior samples the whitened coordinates of
    :mod:`brdf_infer.posterior` under the scene's ``[priors]`` (:attr:`~ModelFamily.as_params`).
    """

    def as_params(p: Physical) -> Params:
        return Params(*(jnp.asarray(p[name], float) for name in PARAM_NAMES))

    def constants_of(p: Physical) -> HemisphereConstants:
        return draw_constants(constants, dphi_free, p)

    units = {
        "brdf0": "sr⁻¹",
        "a1": "deg⁻²",
        "a2": "deg^(−1−α)",
        "a3": "deg^(−2−α)",
        "alpha": "-",
        "theta_s0": "deg",
    }
    return ModelFamily(
        REFERENCE_FAMILY,
        (*PARAM_NAMES, DPHI_NAME) if dphi_free else PARAM_NAMES,
        {**units, DPHI_NAME: "-"} if dphi_free else units,
        (),
        lambda z: z,
        lambda ti, t, phi, p: log_brdf_hemisphere(ti, t, phi, as_params(p), fold, constants_of(p)),
        lambda ti, p: jnp.exp(log_tis(jnp.atleast_1d(ti), as_params(p), fold, constants_of(p))[0]),
        exact_tis=False,
        title="Eqs. (8), (10)",
        as_params=as_params,
        fold=fold,
        constants=constants,
        log_brdf_inplane=lambda ti, ts, p: log_brdf_inplane(ti, ts, as_params(p), fold, constants),
        log_tis_draws=lambda theta, p: log_tis(theta, as_params(p), fold, constants_of(p)),
        dphi_free=dphi_free,
        amplitudes=("brdf0",),
    )


def check_family_name(name: str, *, file: str | Path | None = None, field: str = "model") -> None:
    """Raises BadInputError naming ``file`` and ``field`` when ``name`` is not one of
    :data:`FAMILY_NAMES`."""
    if name not in FAMILY_NAMES:
        raise BadInputError(
            f"unknown model family {name!r} (known: {', '.join(FAMILY_NAMES)})",
            file=file,
            field=field,
        )


def run_family_name(attrs) -> str:
    """The family of a posterior run from its ``posterior`` group's attributes: ``model``;
    runs written before it was recorded are ``strumik2024``'s."""
    return str(attrs.get("model", REFERENCE_FAMILY))


def family(
    name: str,
    fold: bool = False,
    constants: HemisphereConstants = PAPER_CONSTANTS,
    dphi_free: bool = False,
):
    """The family called ``name`` (``fold``, ``constants`` and ``dphi_free`` serve
    ``strumik2024`` only: the other families have no Eqs. 8 and 10).

    Raises:
        KeyError: no such family.
    """
    if name == REFERENCE_FAMILY:
        return strumik_family(fold, constants, dphi_free)
    return FAMILIES[name]
