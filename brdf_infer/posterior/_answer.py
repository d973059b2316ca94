"""What a run's answer rests on: the three records ``summary.json`` adds beside the answer.

* ``"width"``: what carries each headline interval's width (:mod:`._width`);
* ``"learned"``: which parameters and noise scales the data taught (:mod:`._learned`);
* ``"reference"``: where the scene's published values fall in the posterior (:mod:`._reference`);
* ``"targets"``: the headline for the sample(s) measured, the coating and a new part, and
  where τ comes from (:mod:`._targets`). The width record describes the coating's interval.

All three compare the posterior with the physical prior, drawn once here
(:data:`PRIOR_DRAWS` draws, :func:`brdf_infer.posterior.prior_draws`). The width record's
variants and the learned record read the draws PSIS-LOO reads
(:data:`~brdf_infer.posterior._results.LOO_VALUES`: all on a small table, 250 a chain on a
whole one, where each variant's joint likelihood is a pass over every row and draw); the
run's own intervals and the reference record read every draw.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from brdf_infer.posterior._bands import FAMILY_TIS_DRAWS, draws_physical, evenly_spaced
from brdf_infer.posterior._learned import learned_record
from brdf_infer.posterior._model import PosteriorModel
from brdf_infer.posterior._power_scaling import log_likelihood_draws
from brdf_infer.posterior._prior import prior_draws
from brdf_infer.posterior._reference import reference_record
from brdf_infer.posterior._refit import VARIANT_CHAINS, VARIANT_DRAWS, refit
from brdf_infer.posterior._results import loo_sites
from brdf_infer.posterior._samplers import Draws, Refused
from brdf_infer.posterior._targets import (
    NEW_PART_EFFECT,
    SAMPLE_EFFECT,
    targets_record,
    tau_source,
)
from brdf_infer.posterior._width import (
    HEADLINE_TIS_DEG,
    Refitted,
    headline_draws,
    width_attribution,
)
from brdf_infer.tables.measurements import Measurements

PRIOR_DRAWS = 4000  # the prior predictive's 2.5 % quantile from ~100 draws beyond it


def headline_angles(model: PosteriorModel, band_angles: Sequence[float]) -> list[float]:
    """The incidence angles of the headline TIS [deg]: the bands' angles, 70° and every angle
    a ``[reference]`` value names."""
    named = [r.tis_angle_deg for r in model.scene.references]
    angles = {*map(float, band_angles), HEADLINE_TIS_DEG}
    angles.update(angle for angle in named if angle is not None)
    return sorted(angles)


def _refit(draws: Draws, seed: int, tis_angles: Sequence[float]):
    """A variant's headline draws from a new posterior of it (:class:`Refitted`) by the one
    refitter (:func:`~brdf_infer.posterior._refit.refit`: importance sampling from the run's
    draws, else the run's sampler through its compiled program where it serves the variant,
    a NUTS refit held to the one convergence rule), :data:`~._refit.VARIANT_CHAINS` ×
    :data:`~._refit.VARIANT_DRAWS` draws (at most the run's); None where it is refused (an
    emcee run's variants: reported unreliable)."""

    def resample(variant: PosteriorModel) -> Refitted | None:
        sampled = refit(draws, variant, chains=VARIANT_CHAINS, count=VARIANT_DRAWS, seed=seed)
        if isinstance(sampled, Refused):
            return None
        physical = draws_physical(sampled.draws.sites, variant.products)
        flat = headline_draws(variant.products, physical, tis_angles)
        shape = (sampled.record["chains"], sampled.record["draws"])
        headline = {name: values.reshape(shape) for name, values in flat.items()}
        return Refitted(headline, sampled.record, sampled.draws.sites)

    return resample


def thinned_sites(sites: dict[str, np.ndarray], count: int) -> dict[str, np.ndarray]:
    """At most ``count`` draws of ``sites`` (chains, draws, ...), evenly spaced in each chain."""
    chains, draws = np.shape(next(iter(sites.values())))[:2]
    kept = np.unique(np.linspace(0, draws - 1, max(1, count // chains)).round().astype(int))
    return {name: np.asarray(values)[:, kept] for name, values in sites.items()}


def answer_records(
    model: PosteriorModel,
    measurements: Measurements,
    draws: Draws,
    band_angles: Sequence[float],
    with_tis: bool,
    seed: int,
    refit: bool = True,
    run_elpd_i: np.ndarray | None = None,
    reff: float = 1.0,
    effects: dict[str, np.ndarray] | None = None,
    target: str = "coating",
) -> dict[str, Any]:
    """``{"width", "learned", "reference", "targets"}`` of a run (module docstring).

    Args:
        model: the run's posterior model.
        measurements: its rows.
        draws: its draws.
        band_angles: the incidence angles of its bands [deg].
        with_tis: the run reports a TIS (its family and scene have one).
        seed: the run's seed (the prior draws use ``seed + 11``).
        refit: sample a variant anew where reweighting is unreliable (else it is reported
            unreliable).
        run_elpd_i: the run's PSIS-LOO terms (of the draws :func:`loo_sites` keeps), which
            the alternatives' are compared with (None: no Δelpd).
        reff: the draws' relative efficiency (PSIS).
        effects: each draw's sample effects, ``{"sample_effect": (draws, samples),
            "new_part_effect": (draws,)}`` (:mod:`._targets`; None: none, every target the
            coating's).
        target: the target the run's bands describe.
    """
    angles = headline_angles(model, band_angles) if with_tis else []
    member = model.products  # the headline describes the products' BRDF ([outputs] fold)
    physical = draws_physical(draws.sites, member)
    prior = prior_draws(model, PRIOR_DRAWS, seed + 11, frozenset(draws.sites))
    resample = _refit(draws, seed, angles) if refit else None
    sites, thinning = loo_sites(draws.sites, len(measurements))
    count = next(iter(physical.values())).size
    if effects is None:
        samples = len(model.sample_names)
        effects = {SAMPLE_EFFECT: np.zeros((count, samples)), NEW_PART_EFFECT: np.zeros(count)}
    if member.log_tis_draws is None and angles:  # a 2-D quadrature a TIS: the bands' draws
        sites, thinning = thinned_sites(sites, FAMILY_TIS_DRAWS), 2.0
        physical = evenly_spaced(physical, FAMILY_TIS_DRAWS)  # the TIS band's own draws
        prior = evenly_spaced(prior, FAMILY_TIS_DRAWS)
        effects = evenly_spaced(effects, FAMILY_TIS_DRAWS)
    headline = headline_draws(member, physical, angles)
    prior_headline = headline_draws(member, draws_physical(prior, member), angles)
    read = headline
    if thinning > 1:
        read = headline_draws(member, draws_physical(sites, member), angles)
    log_likelihood = log_likelihood_draws(model, sites)  # once, for both records
    width = width_attribution(
        model,
        measurements,
        sites,
        read,
        prior_headline,
        resample,
        log_likelihood,
        headline,
        run_elpd_i,
        reff,
    )
    learned = learned_record(model, sites, prior, log_likelihood)
    targets = targets_record(
        headline,
        effects[SAMPLE_EFFECT],
        effects[NEW_PART_EFFECT],
        model.sample_names,
        target,
        tau_source(model, learned),
    )
    return {
        "width": width,
        "learned": learned,
        "targets": targets,
        "reference": reference_record(
            model.scene.references,
            {**headline, **physical},
            np.shape(next(iter(draws.sites.values())))[0],
        ),
    }
