"""Learned from the data, or set by its prior: one rule for every parameter and noise scale.

For each sampled quantity, on the coordinate its prior is written on (ln BRDF0, b1–b3, α, θs0
for Eq. 7; a family's own coordinates; the noise scales themselves):

* the **contraction** 1 − var_post / var_prior (Schad, Betancourt & Vasishth 2021, "Toward a
  principled Bayesian workflow in cognitive science", Psychol. Methods 26, 103): 0 when the
  data taught nothing, near 1 when they pin it down. The prior variance is that of draws of
  the physical prior (:func:`brdf_infer.posterior.prior_draws`), so it includes the energy
  truncation;
* the **prior sensitivity**: the power-scaling sensitivity to the prior
  (:func:`brdf_infer.posterior.power_scaling`; Kallioinen et al. 2023), how far the posterior
  would move were the prior made a little stronger or weaker (Eq. 7's family; other families
  are judged by contraction alone).

A quantity is called **learned** when the data contract it: contraction ≥
:data:`LEARNED_CONTRACTION` (the posterior sd at most 71 % of the prior's); otherwise it is
**set by its prior**, and tables and the report name its prior's scale. A learned quantity
whose prior sensitivity reaches :data:`SENSITIVITY_THRESHOLD` (priorsense's threshold) is
called learned but *prior-sensitive*: the data contract it, yet a somewhat different prior
would move it (on the bundled data b1–b3 and α, through α's informative prior; θs0 is not
learned at all).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from brdf_infer.model.params import DPHI_NAME
from brdf_infer.posterior._model import DPHI_SITE, PosteriorModel
from brdf_infer.posterior._power_scaling import SENSITIVITY_THRESHOLD, power_scaling

LEARNED_CONTRACTION = 0.5
# the site of each Eq. (7) parameter's prior coordinate (θs0 in degrees: ratios of variances
# do not depend on the scale)
PAPER_COORDINATES = {
    "brdf0": "log_brdf0",
    "a1": "b1",
    "a2": "b2",
    "a3": "b3",
    "alpha": "alpha",
    "theta_s0": "theta_s0",
}


def coordinates(model: PosteriorModel) -> dict[str, str]:
    """Quantity name → the site of its prior coordinate, for every sampled quantity."""
    member = model.family
    if member.paper_parameters:
        names = {n: PAPER_COORDINATES[n] for n in model.scene.free_parameters}
        if member.dphi_free:
            names[DPHI_NAME] = DPHI_SITE
    else:
        names = {c.site: c.site for c in member.coordinates}
    errors = model.errors
    if errors.learns_sample_sd:
        names["sample_sd"] = "sample_sd"
    if errors.model == "generative" and errors.learns_repeatability:
        names["repeatability"] = "repeatability"
    return names


def prior_scale_words(model: PosteriorModel, name: str) -> str:
    """The scale of ``name``'s prior in words (for "set by its prior (scale …)")."""
    if name == "sample_sd":
        return model.errors.sample_sd_prior_words()
    if name == "repeatability":
        return f"half-normal, scale {model.errors.repeatability_sd_prior:g}"
    prior = model.scene.priors.get(name) if model.family.paper_parameters else None
    if prior is None:
        return "the family's default prior"
    if prior.kind == "uniform":
        return f"uniform {prior.lower:g} to {prior.upper:g}"
    if name == DPHI_NAME:  # a factor on the article's Δφ, its prior on the logarithm
        low, high = np.exp(prior.loc + np.array([-1.96, 1.96]) * prior.scale)
        return f"lognormal, sd {prior.scale:g} in ln: ×{low:.2g}–×{high:.2g} of the article's Δφ"
    return f"{prior.kind.replace('_', ' ')}, sd {prior.scale:g}"


def learned_record(
    model: PosteriorModel,
    sites: dict[str, np.ndarray],
    prior_sites: dict[str, np.ndarray],
    log_likelihood: np.ndarray | None = None,
) -> dict[str, dict[str, Any]]:
    """The ``"learned"`` record of a run: ``{NAME: {"contraction", "prior_sensitivity",
    "learned", "prior_sensitive", "coordinate", "prior", "words"}}`` (module docstring).

    Args:
        model: the run's posterior model.
        sites: its draws, (chains, draws, ...).
        prior_sites: draws of its physical prior (leading axis the draws).
        log_likelihood: the joint ln p(y | θ) of every draw, (chains, draws), where the caller
            has it (None: computed by the power-scaling).
    """
    names = coordinates(model)
    missing = [site for site in names.values() if site not in sites or site not in prior_sites]
    names = {n: s for n, s in names.items() if s not in missing}
    sensitivity: dict[str, Any] = {}
    if model.family.paper_parameters and names:
        quantities = {n: np.asarray(sites[s]) for n, s in names.items()}
        sensitivity = power_scaling(model, sites, quantities, log_likelihood)
    record = {}
    for name, site in names.items():
        posterior_var = float(np.var(np.asarray(sites[site]).reshape(-1)))
        prior_var = float(np.var(np.asarray(prior_sites[site]).reshape(-1)))
        contraction = 1.0 - posterior_var / prior_var if prior_var > 0 else 0.0
        prior_sensitivity = sensitivity.get(name, {}).get("prior")
        record[name] = {
            "contraction": contraction,
            "prior_sensitivity": prior_sensitivity,
            "learned": bool(contraction >= LEARNED_CONTRACTION),
            "prior_sensitive": bool(
                prior_sensitivity is not None and prior_sensitivity >= SENSITIVITY_THRESHOLD
            ),
            "coordinate": site,
            "prior": prior_scale_words(model, name),
        }
        record[name]["words"] = learned_words(record[name])
    return record


def learned_words(entry: dict[str, Any]) -> str:
    """ "learned" or "set by its prior (…)" for one quantity of :func:`learned_record`."""
    if not entry["learned"]:
        return f"set by its prior ({entry['prior']})"
    if entry.get("prior_sensitive"):
        return f"learned, prior-sensitive ({entry['prior_sensitivity']:.2f})"
    return "learned"
