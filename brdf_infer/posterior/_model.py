"""The NumPyro model of a scene: priors, reparametrisation and the ln R likelihood.

One model serves every sampler and the simulations: NUTS runs it, emcee samples its
potential, SBC draws data sets from it. The data are an argument (:class:`ModelData`, a pytree
of arrays), so one compilation serves every data set of the same shape.

Likelihood. The scene's error model (:mod:`brdf_infer.model.error_model`): for ``generative`` one
multivariate normal of the rows' ln R with covariance D + W Wᵀ, marginalised over the sample,
calibration and (linearised) angle effects; with ``angle_method = "latent"`` the angle errors
are sampled as latent variables instead. For ``spread`` independent normals.

Reparametrisation. For fixed (α, θs0) the model's ln R is linear in the coefficients
c = (ln BRDF0, b1, b2, b3) — the paper's own observation (Sec. 4.2: "for fixed values of
parameters α and θs0, the other parameters … can be found … using the linear regression").
In c and (α, θs0) the posterior is a curved ridge whose shape depends on where the scene
measured. The sampler therefore moves whitened coefficients u with

    c = m(α, θs0, scales) + L(α, θs0, scales)⁻ᵀ u,

m and L Lᵀ the mean and precision of c in the linear-Gaussian regression of the measured ln R
on the design at (α, θs0) — with the scene's priors on c (as normals) and the rows' covariance
without its angle terms (generalised least squares, so that shared sample and calibration
effects widen the level as they should). Rows out of the plane of incidence, where Eq. (8)
blends two branches and c no longer enters linearly, are left out of this regression (they stay
in the likelihood). That is a smooth bijection for every
(α, θs0, scales), so with its log-Jacobian −Σ ln Lᵢᵢ and the exact prior of c the target
stays exactly the scene's posterior; but u is close to N(0, I) and nearly independent of
(α, θs0) for *any* measurement geometry, where the earlier anchor reparametrisation depended
on the data covering three incidence angles above every θs0 the prior allows. Coefficients
the scene fixes stay fixed; ``reparametrise=False`` samples the c directly.

Energy conservation. The physical prior truncates the priors to coatings with TIS ≤ 1 −
margin (:mod:`brdf_infer.model._energy`), which is an upper bound on ln BRDF0 given the other
parameters. Where ln BRDF0 is a free whitened coefficient, its value from the whitening is
mapped below that bound by a smooth bijection onto (−∞, bound), its log-Jacobian added to the
whitening's: every point the sampler reaches conserves energy, the target is still exactly the
truncated posterior, and NUTS meets no wall. Elsewhere the truncation is a factor, −∞ beyond.

The likelihood's pieces are in :mod:`._likelihood`, the whitening's in :mod:`._whitening`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist

from brdf_infer._internal.stored_programs import StoredFunction, register_tree_types
from brdf_infer.errors import BadInputError
from brdf_infer.model import (
    BOUND_GAP,
    ENERGY_MAP_SOFTNESS,
    ModelFamily,
    Physical,
    below_bound,
    energy_log_factor,
    log_brdf0_bound,
    log_fold,
)
from brdf_infer.model.coordinates import ANGLE_SCALE_DEG, from_internal
from brdf_infer.model.error_model import NoiseScales, angle_slopes, covariance_factors
from brdf_infer.model.params import DPHI_NAME, HemisphereConstants, Params, with_dphi_scale
from brdf_infer.model.priors import Prior
from brdf_infer.posterior._likelihood import (
    LikelihoodParts,
    ModelData,
    build_model_data,
    disjoint_columns,
    drawn_noise_scales,
    mask_rows,
    observe,
    sample_noise_scales,
)
from brdf_infer.posterior._whitening import (
    gaussian_moments,
    linear_design,
    whitened_coefficients,
)
from brdf_infer.predict.observations import family_log_reflectance_at, log_reflectance
from brdf_infer.scene import Scene
from brdf_infer.tables.measurements import Measurements

# the draws' likelihood parts take the noise scales and return the parts: tree types a stored
# program must name (jax.export refused every such program in every run without them)
register_tree_types((NoiseScales, LikelihoodParts))

LINEAR = ("brdf0", "a1", "a2", "a3")  # priors of c = (ln BRDF0, b1, b2, b3)
LINEAR_SITES = ("log_brdf0", "b1", "b2", "b3")
NOISE_SITES = ("sample_sd", "repeatability")
ENERGY_SITE = "energy_conservation"  # the physical prior's truncation (brdf_infer.model._energy)
DPHI_SITE = "log_dphi_scale"  # ln of Eq. (8)'s Δφ factor, under [priors.dphi_scale]


def prior_distribution(prior: Prior, scale: float = 1.0) -> dist.Distribution:
    """The NumPyro distribution of a (non-fixed) prior, its coordinate divided by ``scale``."""
    loc, sd, low, high = (
        prior.loc / scale,
        prior.scale / scale,
        prior.lower / scale,
        prior.upper / scale,
    )
    if prior.kind == "normal":
        return dist.Normal(loc, sd)
    if prior.kind == "truncated_normal":
        return dist.TruncatedNormal(  # an infinite bound is no bound (None keeps it finite)
            loc,
            sd,
            low=low if math.isfinite(low) else None,
            high=high if math.isfinite(high) else None,
        )
    if prior.kind == "uniform":
        return dist.Uniform(low, high)
    raise ValueError(f"no distribution for a {prior.kind} prior")


@dataclass(frozen=True)
class PosteriorModel:
    """A scene's posterior under a model family: a NumPyro model function of
    :class:`ModelData` and its data.

    One model for every family: the same rows, instrument (Eq. 6) and generative error model,
    one forward path (:func:`brdf_infer.predict.observations.log_reflectance`), so that PSIS-LOO
    compares the BRDF families and nothing else. A family with Eq. (7)'s parameters
    (:attr:`~brdf_infer.model.ModelFamily.paper_parameters`) is sampled under the scene's
    ``[priors]``, its linear coefficients whitened (module docstring); any other family in
    its internal coordinates under their default priors, its physical parameters as
    deterministic sites.

    Attributes:
        scene: the scene (priors, error model, model components).
        family: the BRDF family.
        data: the scene's own data (the default argument of the model).
        whiten: sample the whitened coefficients u instead of c (module docstring; Eq. 7's
            family only).
        sample_names: the physical samples, in order of appearance.
        row_samples: the physical sample of each row.
        row_series: index of each row's series (in order of appearance).
        sigma_scale: multiplies the likelihood's σ when fitting (1; other values only for a
            planted fault in simulation-based calibration, whose simulations keep 1).
        drop_log_jacobian: leave the whitening's log-Jacobian −Σ ln Lᵢᵢ (with the energy
            map's, module docstring) out of the density (False; True only for a planted fault
            in simulation-based calibration, which must then fail: the target is no longer the
            scene's posterior).
    """

    scene: Scene
    family: ModelFamily
    data: ModelData
    whiten: bool
    sample_names: tuple[str, ...]
    row_samples: tuple[str, ...]
    row_series: tuple[int, ...]
    sigma_scale: float = 1.0
    drop_log_jacobian: bool = False

    @property
    def errors(self):
        return self.scene.errors

    @property
    def products(self) -> ModelFamily:
        """The family the run's products describe: its own with the scene's products fold
        (``[outputs] fold``, Eq. 10; default the physical BRDF), whatever the likelihood's
        (``[model] fold``, what the instrument measured)."""
        if not self.family.paper_parameters:
            return self.family
        return self.family.with_fold(self.scene.outputs.fold)

    def __call__(self, data: ModelData | None = None, mode: str = "fit") -> None:
        """The NumPyro model.

        Args:
            data: the rows (default: the scene's).
            mode: ``fit`` (``obs`` observed), ``predict`` (``obs`` drawn, e.g. for the
                posterior predictive) or ``simulate`` (every parameter drawn from its prior
                directly, without the reparametrisation, and ``obs`` drawn: the generative
                model of SBC).
        """
        data = self.data if data is None else data
        scales = sample_noise_scales(self.errors, data.noise)
        physical = self._physical(data, scales, whiten=self.whiten and mode != "simulate")
        rows = data.rows
        if self.errors.angles_on and self.errors.angle_method == "latent":
            theta_i, theta_s = self._latent_angles(data, scales)
            member = self.family
            mean = (
                family_log_reflectance_at(member, theta_i, theta_s, physical, rows)
                - family_log_reflectance_at(
                    member, rows.theta_i_deg, rows.theta_s_deg, physical, rows
                )
                + log_reflectance(member, physical, rows)
            )
            parts = self.likelihood_parts(physical, scales, data, mean=mean, angles=False)
        else:
            parts = self.likelihood_parts(physical, scales, data)
        observe(parts, data, mode, self.sigma_scale, spread=self.errors.model == "spread")

    def _physical(self, data: ModelData, scales: NoiseScales, whiten: bool) -> Physical:
        """The family's physical parameters of one draw, sampled (class docstring)."""
        if self.family.paper_parameters:
            if not self.family.dphi_free:
                return self._parameters(data, scales, whiten, self.family.constants)._asdict()
            prior = prior_distribution(self.scene.priors[DPHI_NAME])
            scale = numpyro.deterministic(DPHI_NAME, jnp.exp(numpyro.sample(DPHI_SITE, prior)))
            constants = with_dphi_scale(self.family.constants, scale)
            params = self._parameters(data, scales, whiten, constants)
            return {**params._asdict(), DPHI_NAME: scale}
        internal = {
            c.site: numpyro.sample(c.site, prior_distribution(c.prior))
            for c in self.family.coordinates
        }
        physical = self.family.to_physical(internal)
        for name in self.family.parameters:
            if name not in internal:  # a coordinate that is its own parameter (g, S)
                numpyro.deterministic(name, physical[name])
        return physical

    def _parameters(
        self, data: ModelData, scales: NoiseScales, whiten: bool, constants: HemisphereConstants
    ) -> Params:
        """Eq. (7)'s parameters of one draw, sampled (``constants``: Eq. 8's of the draw, for
        the physical prior's TIS)."""
        priors = self.scene.priors

        def parameter(name: str, site: str, scale: float = 1.0):
            prior = priors[name]
            if prior.fixed:
                return jnp.asarray(prior.value / scale)
            return numpyro.sample(site, prior_distribution(prior, scale))

        alpha = parameter("alpha", "alpha")
        if priors["alpha"].fixed:
            numpyro.deterministic("alpha", alpha)
        t_s0 = parameter("theta_s0", "t_s0", ANGLE_SCALE_DEG)
        free = [k for k, name in enumerate(LINEAR) if not priors[name].fixed]
        bound = None  # of ln BRDF0, where the whitened coordinates map it below its bound
        if whiten and free:
            coefficients, bound = self._whitened(data, scales, alpha, t_s0, free, constants)
        else:
            coefficients = [
                parameter(name, site) for name, site in zip(LINEAR, LINEAR_SITES, strict=True)
            ]
        log_brdf0, b1, b2, b3 = coefficients
        params = from_internal(
            jnp.stack(jnp.broadcast_arrays(log_brdf0, b1, b2, b3, alpha, t_s0), axis=-1)
        )
        for name in ("brdf0", "a1", "a2", "a3", "theta_s0"):
            numpyro.deterministic(name, getattr(params, name))
        # the physical prior: no mass on coatings with TIS > 1 (simulations reject such draws,
        # brdf_infer.studies.sbc.simulate); where the whitened coordinates map ln BRDF0 below
        # its bound, the same check from that bound (0 at every point they reach, no second TIS)
        if bound is None:
            energy = energy_log_factor(params, constants)
        else:
            energy = jnp.where(jax.lax.stop_gradient(log_brdf0 <= bound), 0.0, -jnp.inf)
        numpyro.factor(ENERGY_SITE, energy)
        return params

    def _whitened(
        self,
        data: ModelData,
        scales: NoiseScales,
        alpha,
        t_s0,
        free: list[int],
        constants: HemisphereConstants,
    ):
        """The coefficients c from whitened coordinates u (module docstring), and the bound
        of ln BRDF0 (:func:`brdf_infer.model.log_brdf0_bound`, at the draw's Eq. 8
        ``constants``: its own out-of-plane width) where it is free and mapped below it, else
        None."""
        priors = self.scene.priors
        rows, noise = data.rows, data.noise
        fixed_values = jnp.array(
            [priors[name].value if priors[name].fixed else 0.0 for name in LINEAR]
        )
        design = linear_design(rows, alpha, t_s0)
        fold = self.family.fold
        offset = rows.log_aperture + design @ fixed_values
        if fold:
            offset = offset + jnp.where(
                rows.theta_s_deg >= 0, log_fold(rows.theta_s_deg, constants), 0.0
            )
        zero = jnp.zeros_like(rows.theta_i_deg)
        factor, diagonal = covariance_factors(noise, scales, zero, zero)  # no angle terms
        factor = factor[:, : factor.shape[1] - noise.rotation_members.shape[-1]]  # zero there
        regression = data.mask > 0  # padding rows leave the regression
        if rows.phi_s_deg is not None:  # Eq. (7)'s linearity holds in the plane only
            regression = regression & ~jnp.isfinite(rows.phi_s_deg)
        factor, diagonal = mask_rows(regression, factor, diagonal)
        moments = np.array([gaussian_moments(priors[LINEAR[k]]) for k in free])
        standard = numpyro.sample(
            "linear_std", dist.ImproperUniform(dist.constraints.real, (), (len(free),))
        )

        def solve(u):
            return whitened_coefficients(
                jnp.where(regression[:, None], design[:, free], 0.0),
                jnp.where(regression, rows.log_reflectance - offset, 0.0),
                factor * self.sigma_scale,
                diagonal * self.sigma_scale**2,
                jnp.asarray(moments[:, 0]),
                jnp.asarray(moments[:, 1]),
                u,
                disjoint_columns(data),
            )

        # c is affine in u: ∂c₀/∂u₀ = 1/L₀₀, the regression's sd of ln BRDF0 given b1–b3
        first = jnp.zeros(len(free)).at[0].set(1.0)
        (values, log_jacobian), (slope, _) = jax.jvp(solve, (standard,), (first,))
        bound = None
        if free[0] == 0:  # ln BRDF0 free: mapped below its energy bound (module docstring)
            bound = self._log_brdf0_bound(values, fixed_values, free, alpha, t_s0, constants)
            scale = ENERGY_MAP_SOFTNESS * slope[0]
            mapped, log_slope = below_bound(values[0], bound - BOUND_GAP, scale)
            values = values.at[0].set(mapped)
            log_jacobian = log_jacobian + log_slope
        log_prior = sum(
            prior_distribution(priors[LINEAR[k]]).log_prob(values[position])
            for position, k in enumerate(free)
        )
        if self.drop_log_jacobian:  # a planted fault (SBC), never in a fit
            log_jacobian = 0.0
        numpyro.factor("coefficient_prior", log_prior + log_jacobian)
        coefficients = list(fixed_values)
        for position, k in enumerate(free):
            coefficients[k] = numpyro.deterministic(LINEAR_SITES[k], values[position])
        return coefficients, bound

    def _log_brdf0_bound(self, values, fixed_values, free: list[int], alpha, t_s0, constants):
        """The largest ln BRDF0 that conserves energy with the other parameters of a draw
        (:func:`brdf_infer.model.log_brdf0_bound`): ``values`` the free coefficients of c,
        ``fixed_values`` the fixed ones."""
        b = [values[free.index(k)] if k in free else fixed_values[k] for k in (1, 2, 3)]
        unit = from_internal(jnp.stack([jnp.zeros(()), *b, alpha, t_s0]))  # BRDF0 = 1
        return log_brdf0_bound(unit, constants)

    def _latent_angles(self, data: ModelData, scales: NoiseScales):
        """Perturbed angles (θi + ε, θs + s ε + η) with ε per rotation setting, η per row and
        s the rotation coupling (:mod:`brdf_infer.model.error_model`).

        A setting of two or more rows has its ε in ``rotation_error_std``; a row alone in its
        setting (``rotation_alone``) has its own in ``rotation_alone_error_std``, a variable per
        row that only those rows use (a static shape: the data are an argument).
        """
        noise = data.noise
        members = noise.rotation_members
        with numpyro.plate("rotation_settings", members.shape[1]):
            rotation = numpyro.sample("rotation_error_std", dist.Normal(0.0, 1.0))
        with numpyro.plate("camera_rows", members.shape[0]):
            camera = numpyro.sample("camera_error_std", dist.Normal(0.0, 1.0))
            alone = numpyro.sample("rotation_alone_error_std", dist.Normal(0.0, 1.0))
        epsilon = scales.rotation_deg * (members @ rotation + noise.rotation_alone * alone)
        eta = scales.camera_deg * camera
        rows = data.rows
        coupling = data.noise.theta_s_per_rotation
        return rows.theta_i_deg + epsilon, rows.theta_s_deg + coupling * epsilon + eta

    def likelihood_parts(
        self,
        physical: Physical,
        scales: NoiseScales,
        data: ModelData | None = None,
        *,
        mean: jnp.ndarray | None = None,
        angles: bool = True,
    ) -> LikelihoodParts:
        """Mean and covariance factors of the rows' ln R for one draw (Eq. 6 in log space).

        Args:
            physical: the draw's physical parameters (for Eq. 7 also a :class:`Params`).
            scales: the draw's noise scales.
            data: the rows (default: the scene's).
            mean: the mean, if already computed (latent angles).
            angles: include the linearised angle terms (off for latent angles).
        """
        data = self.data if data is None else data
        rows, noise = data.rows, data.noise
        if isinstance(physical, Params):  # Eq. (7)'s parameters as a record
            physical = physical._asdict()
        if mean is None:
            mean = log_reflectance(self.family, physical, rows)
        if angles and self.errors.angles_on:
            g_rot, g_cam = angle_slopes(
                lambda ti, ts: family_log_reflectance_at(self.family, ti, ts, physical, rows),
                rows.theta_i_deg,
                rows.theta_s_deg,
                noise.theta_s_per_rotation,
            )
        else:
            g_rot = g_cam = jnp.zeros_like(mean)
        factor, diagonal = covariance_factors(noise, scales, g_rot, g_cam)
        return LikelihoodParts(mean, factor, diagonal)

    def draw_parts(self, sites: dict, data: ModelData | None = None) -> LikelihoodParts:
        """:meth:`likelihood_parts` of every draw (leading axis) of a posterior's sites, on
        ``data`` (default: the scene's; another data set of the same shape shares the
        compiled program)."""
        data = self.data if data is None else data
        physical = {name: jnp.asarray(sites[name]) for name in self.family.parameters}
        count = next(iter(physical.values())).shape[0]
        scales = drawn_noise_scales(self.errors, data.noise, sites, count)
        return _draw_parts_program(self)(physical, scales, data)


def model_identity(model: PosteriorModel) -> tuple:
    """Every value of ``model`` a compiled program of it may close over, for the key of a
    stored program (:mod:`brdf_infer._internal.stored_programs`): its scene, its family's
    fields but for its functions (whose code the key's source digest covers), its options, its
    row labels and its data's values (an argument of the programs, kept in the key so that
    nothing the rows shape can be baked in unseen)."""
    family = tuple(
        (field.name, getattr(model.family, field.name))
        for field in dataclasses.fields(model.family)
        if not callable(getattr(model.family, field.name))
    )
    return (
        model.scene,
        family,
        model.whiten,
        model.sample_names,
        model.row_samples,
        model.row_series,
        model.sigma_scale,
        model.drop_log_jacobian,
        tuple(jax.tree_util.tree_leaves(model.data)),
    )


def _draw_parts_program(model: PosteriorModel):
    """:meth:`PosteriorModel.likelihood_parts` vmapped over draws and jitted, once per model
    object and kept on it (``_draw_parts``; a model holds arrays, so it cannot key a cache):
    the program goes when the model goes. The data are an argument, not a constant, so one
    compilation serves every data set of a shape; a warm run loads it without tracing
    (:class:`~brdf_infer._internal.stored_programs.StoredFunction`)."""
    if "_draw_parts" not in model.__dict__:
        model.__dict__["_draw_parts"] = StoredFunction(
            jax.vmap(lambda p, s, d: model.likelihood_parts(p, s, d), (0, 0, None)),
            ("likelihood parts", model_identity(model)),
        )
    return model.__dict__["_draw_parts"]


def build_posterior_model(
    scene: Scene,
    measurements: Measurements,
    member: ModelFamily | None = None,
    *,
    reparametrise: bool = True,
) -> PosteriorModel:
    """The posterior model of ``scene`` on ``measurements`` under the family ``member``.

    Args:
        scene: priors, error model, components.
        measurements: every row, each sample separately.
        member: the BRDF family (default: Eq. 7 with the scene's fold and constants).
        reparametrise: sample whitened coefficients (off: the coefficients themselves).

    Raises:
        BadInputError: the scene asks for latent angles under a family without Eq. (7)'s
            parameters.
    """
    if member is None:
        member = scene.family()
    elif member.paper_parameters and (
        member.fold != scene.model.fold or member.constants != scene.model.constants
    ):  # the run records the scene's; the likelihood must use the same
        raise ValueError(f"{member.name}'s fold and constants differ from the scene's")
    latent = scene.errors.angles_on and scene.errors.angle_method == "latent"
    if latent and not member.paper_parameters:
        raise BadInputError(
            f"angle_method = 'latent' is available for strumik2024 only, not {member.name}",
            file=scene.path,
            field="errors.angle_method",
        )
    return PosteriorModel(
        scene=scene,
        family=member,
        data=build_model_data(scene, measurements),
        whiten=reparametrise and member.paper_parameters,
        **row_labels(measurements),
    )


def row_labels(measurements: Measurements) -> dict[str, tuple]:
    """``sample_names``, ``row_samples`` and ``row_series`` of a posterior model (class
    attributes of :class:`PosteriorModel`)."""
    series = list(dict.fromkeys(measurements.series))
    return {
        "sample_names": tuple(dict.fromkeys(str(s) for s in measurements.sample)),
        "row_samples": tuple(str(s) for s in measurements.sample),
        "row_series": tuple(series.index(s) for s in measurements.series),
    }
