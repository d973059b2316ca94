"""Which coating a band is for: the sample(s) measured, the coating, or a new part.

The error model (:mod:`brdf_infer.model.error_model`) gives every physical sample j an effect
u_j ~ N(0, τ) on every ln R it measured; the model's parameters describe the population the
samples come from (the *coating*). A sample effect multiplies that sample's BRDF, and so its
TIS, by e^u_j (:meth:`~brdf_infer.model.ModelFamily.scaled`). Three questions, three targets:

* ``measured``: what the sample(s) measured scatter, each conditional on its own effect:
  BRDF × e^u_j with u_j drawn from its conditional given each posterior draw and the data.
  Given the parameters θ and the noise scales, the rows' ln R are Gaussian in the latent
  effects z (standard normal: sample effects u = τ z_s, calibration factors, the linearised
  rotation errors; Cov = D + W Wᵀ), so z | θ, y ~ N(P⁻¹ Wᵀ D⁻¹ r, P⁻¹), P = I + Wᵀ D⁻¹ W,
  r = y − mean (the conjugate normal; a sample of one row, whose τ² sits on D, is a column
  here). Several samples: the BRDF averaged over them (ln of the mean of e^u_j), and each
  one by name.
* ``coating``: the population mean (the model's parameters as sampled; u = 0).
* ``new_part``: a part nobody has measured: u_new ~ N(0, τ), one new effect each draw, τ that
  draw's. What a stray-light budget for a flight part needs.

A scene with one sample answers ``measured`` first (its effect and the coating's level are
one sum that the data locate together, while τ, and so the coating, is set by τ's prior);
a scene with several answers ``coating`` (and ``new_part`` beside it). ``[outputs] target``
or ``--target`` picks another.

τ's source (``tau_source``) says where the spread between parts comes from: this scene's
samples (learned, where the data contract it), another run of the coating (``[errors]
sample_sd_from``), a stated value (``sample_sd``, with its source), or its prior alone.
With angle errors as latent variables the conditional uses the linearised angle terms.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer.errors import BadInputError
from brdf_infer.model import ModelFamily
from brdf_infer.posterior._bands import interval95
from brdf_infer.posterior._blocks import factor_columns, over_draw_blocks
from brdf_infer.posterior._likelihood import ModelData
from brdf_infer.posterior._model import PosteriorModel
from brdf_infer.posterior._results import family_draws, run_posterior_group, sample_index
from brdf_infer.scene import TARGETS

AUTO = "auto"
QUESTIONS = {
    "measured": "what the sample(s) measured scatter, each with its own sample effect",
    "coating": "what the coating scatters: the population mean of its samples",
    "new_part": "what to budget for a part nobody has measured: a new sample effect drawn with τ",
}
# posterior.nc variables holding each draw's effects (ln R): the measured samples' (sample
# dimension) and a new part's
SAMPLE_EFFECT = "sample_effect"
NEW_PART_EFFECT = "new_part_effect"
# and each draw's calibration factors (dimension calibration_group)
CALIBRATION_EFFECT = "calibration_effect"


def chosen_target(requested: str, samples: int) -> str:
    """The target a run's bands describe: ``requested`` unless it is ``auto``, which is
    ``measured`` for one physical sample and ``coating`` for several (module docstring)."""
    if requested != AUTO:
        return requested
    return "measured" if samples == 1 else "coating"


@jax.jit
def _conditional_effects(residual, rest, diagonal, members, tau, calibration_scale):
    """Per draw, mean and covariance of the sample effects u (samples,) and of the
    calibration factors κ (groups,) given the rows (module docstring): ``residual`` y − mean
    (draws, rows), ``rest`` the covariance factor's columns other than the samples' (draws,
    rows, k; the calibration groups' first), ``diagonal`` D without the samples' τ² (draws,
    rows), ``members`` one-hot rows × samples, ``tau`` τ of each draw, ``calibration_scale``
    σ_cal of each calibration column (κ_g = σ_g z_g)."""
    count, groups = members.shape[1], calibration_scale.shape[0]

    def one(r, w_rest, d, t):
        w = jnp.concatenate([t * members, w_rest], axis=1)
        scaled = w / d[:, None]
        precision = jnp.eye(w.shape[1]) + w.T @ scaled
        root = jnp.linalg.cholesky(precision)
        mean = jax.scipy.linalg.cho_solve((root, True), scaled.T @ r)
        covariance = jax.scipy.linalg.cho_solve((root, True), jnp.eye(w.shape[1]))
        kept = slice(count, count + groups)
        return (
            t * mean[:count],
            t**2 * covariance[:count, :count],
            calibration_scale * mean[kept],
            calibration_scale[:, None] * covariance[kept, kept] * calibration_scale[None, :],
        )

    return jax.vmap(one)(residual, rest, diagonal, tau)


def calibration_scales(noise) -> np.ndarray:
    """σ_cal of each calibration group of two or more rows (W's calibration columns) [ln R]."""
    members = np.asarray(noise.calibration_members, float)
    return np.max(np.asarray(noise.calibration_sd, float)[:, None] * members, axis=0)


def effect_moments(
    model: PosteriorModel, sites: dict[str, np.ndarray], data: ModelData | None = None
) -> tuple[np.ndarray, ...]:
    """The conditional mean (draws, samples) and covariance (draws, samples, samples) [ln R]
    of the measured samples' effects u given each posterior draw and the rows (module
    docstring), samples in ``model.sample_names``' order, and the same of the calibration
    factors κ of the groups of two or more rows (:func:`calibration_scales`); zeros where
    the error model has no such effect. ``sites``: (chains, draws, ...); ``data``: the rows
    (default the scene's; a simulated data set of the same layout)."""
    flat = {k: np.reshape(v, (-1, *np.shape(v)[2:])) for k, v in sites.items()}
    count = len(next(iter(flat.values())))
    samples = len(model.sample_names)
    errors = model.errors
    data = model.data if data is None else data
    scale = jnp.asarray(calibration_scales(data.noise))
    groups = int(scale.shape[0])
    if errors.model != "generative":
        return (
            np.zeros((count, samples)),
            np.zeros((count, samples, samples)),
            np.zeros((count, groups)),
            np.zeros((count, groups, groups)),
        )
    members = np.zeros((len(model.row_samples), samples))
    if errors.sample_effects:
        members[np.arange(len(model.row_samples)), sample_index(model)] = 1.0
    members = jnp.asarray(members * np.asarray(data.mask)[:, None])
    shared = data.noise.sample_members.shape[-1]  # the factor's leading columns
    alone = jnp.asarray(data.noise.sample_alone)
    observed = jnp.asarray(data.rows.log_reflectance)
    measured = jnp.asarray(data.mask) > 0

    def compute(block: dict[str, np.ndarray]) -> tuple:
        parts = model.draw_parts(block, data)
        size = len(block[model.family.parameters[0]])
        tau = jnp.asarray(block.get("sample_sd", np.full(size, errors.stated_sample_sd)))
        diagonal = jnp.where(measured, parts.diagonal - alone * tau[:, None] ** 2, 1.0)
        residual = jnp.where(measured, observed - parts.mean, 0.0)
        rest = jnp.where(measured[:, None], parts.factor[..., shared:], 0.0)
        return _conditional_effects(residual, rest, diagonal, members, tau, scale)

    columns = factor_columns(data.noise) + samples
    return tuple(over_draw_blocks(compute, flat, len(model.row_samples), columns))


def _draw_normal(mean: np.ndarray, covariance: np.ndarray, seed: int) -> np.ndarray:
    """One draw of N(mean, covariance) per leading index (a zero covariance allowed)."""
    values, vectors = np.linalg.eigh(covariance)
    root = vectors * np.sqrt(np.clip(values, 0.0, None))[:, None, :]
    normal = np.random.default_rng(seed).standard_normal(mean.shape)
    return mean + np.einsum("dij,dj->di", root, normal)


def latent_effect_draws(
    model: PosteriorModel,
    sites: dict[str, np.ndarray],
    seed: int,
    data: ModelData | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """One draw per posterior draw of every measured sample's effect u_j, (draws, samples),
    and of every calibration factor κ_g, (draws, groups) [ln R], each from its own
    conditional (:func:`effect_moments`; u and κ are drawn apart: each is summarised alone)."""
    mean, covariance, calibration_mean, calibration_covariance = effect_moments(model, sites, data)
    return (
        _draw_normal(mean, covariance, seed),
        _draw_normal(calibration_mean, calibration_covariance, seed + 1),
    )


def new_part_draws(model: PosteriorModel, sites: dict[str, np.ndarray], seed: int) -> np.ndarray:
    """A new part's effect u_new ~ N(0, τ) [ln R], one per posterior draw, τ the draw's (the
    stated τ where it is not sampled; zeros without sample effects)."""
    count = np.size(sites[model.family.parameters[0]])
    tau = np.asarray(sites.get("sample_sd", np.full(count, model.errors.stated_sample_sd)))
    return tau.reshape(-1) * np.random.default_rng(seed + 1).standard_normal(count)


def target_log_factor(
    target: str,
    sample_effects: np.ndarray,
    new_part: np.ndarray,
    sample_names: Sequence[str],
    sample: str | None = None,
) -> np.ndarray:
    """Each draw's ln factor on the coating's BRDF for ``target`` (``sample``: one measured
    sample by name; else the measured samples' mean BRDF, ln mean_j e^u_j).

    Raises:
        BadInputError: ``sample`` with another target, or a sample the run did not measure.
    """
    if sample is not None and target != "measured":
        raise BadInputError("a sample is named for the measured target only", field="sample")
    if target == "coating":
        return np.zeros(len(new_part))
    if target == "new_part":
        return np.asarray(new_part, float)
    effects = np.asarray(sample_effects, float)
    if sample is not None:
        if sample not in sample_names:
            raise BadInputError(
                f"no sample {sample!r} in the run (samples: {', '.join(sample_names)})",
                field="sample",
            )
        return effects[:, list(sample_names).index(sample)]
    peak = np.max(effects, axis=1, keepdims=True)
    return (peak + np.log(np.mean(np.exp(effects - peak), axis=1, keepdims=True)))[:, 0]


def tau_source(model: PosteriorModel, learned: dict[str, Any]) -> str:
    """Where the run's τ comes from, in words (module docstring)."""
    errors = model.errors
    if not errors.sample_effects:
        return "none: the error model has no sample-to-sample effect (new_part = coating)"
    if not errors.learns_sample_sd:
        return f"stated: τ = {errors.stated_sample_sd:g} ({errors.sample_sd_source})"
    entry = learned.get("sample_sd", {})
    if errors.sample_sd_log_kde is not None:
        taught = " and this scene's samples" if entry.get("learned") else ""
        return f"run {errors.sample_sd_from}'s τ posterior (as this scene's prior){taught}"
    samples = len(model.sample_names)
    if entry.get("learned"):
        return f"learned from this scene's {samples} samples"
    return (
        f"set by its prior ({errors.sample_sd_prior_words()}): this scene's {samples} "
        "sample(s) do not teach it; give it from a run of the coating "
        "([errors] sample_sd_from) or state it (sample_sd, sample_sd_source)"
    )


def targets_record(
    headline: dict[str, np.ndarray],
    sample_effects: np.ndarray,
    new_part: np.ndarray,
    sample_names: Sequence[str],
    chosen: str,
    source: str,
) -> dict[str, Any]:
    """The summary's ``"targets"``: ``{"chosen", "tau_source", TARGET: {"question",
    "tis_70deg", "pi_brdf0"}}`` (95 % intervals, None where the run has no such quantity),
    ``measured`` also ``"per_sample"`` by name where the run has several samples.

    Args:
        headline: every draw of the coating's headline quantities (``tis_70deg``,
            ``pi_brdf0`` where the run has them), which a sample effect multiplies by e^u.
        sample_effects, new_part: each draw's effects (:func:`latent_effect_draws`,
            :func:`new_part_draws`).
        sample_names: the measured samples, in the effects' order.
        chosen: the target the run's bands describe.
        source: :func:`tau_source`.
    """

    def intervals(log_factor: np.ndarray) -> dict[str, Any]:
        scale = np.exp(log_factor)
        return {
            name: interval95(headline[name] * scale) if name in headline else None
            for name in ("tis_70deg", "pi_brdf0")
        }

    record: dict[str, Any] = {"chosen": chosen, "tau_source": source}
    for target in TARGETS:
        factor = target_log_factor(target, sample_effects, new_part, sample_names)
        record[target] = {"question": QUESTIONS[target], **intervals(factor)}
    if len(sample_names) > 1:
        record["measured"]["per_sample"] = {
            name: intervals(sample_effects[:, k]) for k, name in enumerate(sample_names)
        }
    return record


def store_effects(
    idata, effects: dict[str, np.ndarray], sample_names: Sequence[str], target: str
) -> None:
    """Add each draw's effects to the run's posterior group (``sample_effect`` with a
    ``sample`` dimension, ``new_part_effect``) and the target its bands describe (attribute
    ``target``), so that products read after the run can take any target
    (:func:`run_log_factor`)."""
    sizes = idata.posterior.sizes
    shape = (sizes["chain"], sizes["draw"])
    idata.posterior[SAMPLE_EFFECT] = (
        ("chain", "draw", "sample"),
        np.asarray(effects[SAMPLE_EFFECT]).reshape(*shape, len(sample_names)),
    )
    idata.posterior[NEW_PART_EFFECT] = (
        ("chain", "draw"),
        np.asarray(effects[NEW_PART_EFFECT]).reshape(shape),
    )
    idata.posterior.coords["sample"] = list(sample_names)
    idata.posterior.attrs["target"] = target


def store_calibration_effects(idata, draws: np.ndarray, names: Sequence[str]) -> None:
    """Add each draw's calibration factors κ_g [ln R] to the run's posterior group
    (``calibration_effect``, dimension ``calibration_group``) where it has any."""
    if not len(names):
        return
    sizes = idata.posterior.sizes
    idata.posterior[CALIBRATION_EFFECT] = (
        ("chain", "draw", "calibration_group"),
        np.asarray(draws).reshape(sizes["chain"], sizes["draw"], len(names)),
    )
    idata.posterior.coords["calibration_group"] = [str(name) for name in names]


def run_log_factor(
    posterior, target: str | None, sample: str | None = None
) -> tuple[str, np.ndarray]:
    """(the target, each draw's ln factor on the coating's BRDF) of a run's ``posterior`` group
    for ``target`` (None: the one its bands describe, attribute ``target``).

    Raises:
        BadInputError: a run written before the targets asked for another than the coating,
            or ``sample`` as :func:`target_log_factor` refuses it.
    """
    if target is None:
        target = "measured" if sample is not None else str(posterior.attrs.get("target", "coating"))
    count = int(posterior.sizes["chain"] * posterior.sizes["draw"])
    if SAMPLE_EFFECT not in posterior:
        if target != "coating" or sample is not None:
            raise BadInputError(
                "this run was written before the measured and new-part targets: rerun "
                "'brdf-infer posterior' for them",
                field="target",
            )
        return target, np.zeros(count)
    effects = np.asarray(posterior[SAMPLE_EFFECT]).reshape(count, -1)
    new_part = np.asarray(posterior[NEW_PART_EFFECT]).reshape(count)
    names = [str(name) for name in np.asarray(posterior["sample"])]
    return target, target_log_factor(target, effects, new_part, names, sample)


def load_run_target(
    run: Path, target: str | None = None, sample: str | None = None
) -> tuple[ModelFamily, dict[str, np.ndarray], str]:
    """(the run's family, every draw of the physical parameters of the BRDF of ``target``,
    the target) of a posterior run: the coating's parameters with each draw's amplitude times
    its target's factor (:func:`run_log_factor`; None: the target of the run's bands).

    Raises:
        BadInputError: as :func:`~brdf_infer.posterior.load_run_family` and
            :func:`run_log_factor`.
    """
    posterior, path = run_posterior_group(run)
    member, physical = family_draws(posterior, None, path)
    target, factor = run_log_factor(posterior, target, sample)
    return member, member.scaled(physical, factor), target
