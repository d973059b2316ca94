"""Calibration factors and campaigns in a run: what each reference measurement's factor κ_g
was learned to be, and how each campaign of a pooled scene (``[campaigns.NAME]``,
:mod:`brdf_infer.scene._campaigns`) fits.

* ``calibration_effects``: κ_g of every calibration group of two or more rows, drawn from its
  conditional given each posterior draw and the rows (the conjugate normal of
  :mod:`._targets`): its prior σ_cal, its posterior median and 95 % interval, and
  ``sd_ratio``, its posterior sd over σ_cal: well below 1 where the rows locate the factor
  (against the other campaigns' rows and the coating's shape), near 1 where only its prior
  does. The factors of one scene share the coating's level: what the rows locate is their
  differences, so in a scene of one calibration group its factor is its prior.
* ``campaigns`` (a pooled scene only): per campaign its file, rows and samples, its own error
  settings, its rows' share of the PSIS-LOO elpd with a standard error (√n × the sd of its
  rows' terms) and the Kolmogorov–Smirnov p of its rows' LOO-PIT. The model check gains
  ``loo_pit_campaigns``: the smallest of those p-values times the number of campaigns
  (Bonferroni), so a campaign the pooled model does not describe fails the run even where the
  other campaigns' rows dilute the pooled LOO-PIT.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from brdf_infer.model.error_model import calibration_group_names, row_campaigns
from brdf_infer.posterior._bands import interval95
from brdf_infer.posterior._loo import uniformity_p_value
from brdf_infer.posterior._model import PosteriorModel
from brdf_infer.posterior._model_check import CHECK_P_VALUE, check, detectable_spread
from brdf_infer.posterior._targets import calibration_scales
from brdf_infer.scene import Scene
from brdf_infer.tables.measurements import Measurements


def campaign_records(
    model: PosteriorModel,
    measurements: Measurements,
    calibration_draws: np.ndarray,
    elpd_i: np.ndarray,
    pit: np.ndarray,
) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """The summary's ``calibration_effects`` (and, for a pooled scene, ``campaigns``) and the
    model check's ``loo_pit_campaigns`` (for two or more campaigns) of a run, from its
    calibration factors' draws (draws, groups) and its rows' LOO terms and LOO-PIT."""
    scene = model.scene
    names = calibration_group_names(scene.errors, measurements)
    records: dict[str, Any] = {
        "calibration_effects": calibration_record(
            names, calibration_draws, calibration_scales(model.data.noise)
        )
    }
    campaigns = campaigns_record(scene, measurements, elpd_i, pit)
    if campaigns is None:
        return records, []
    records["campaigns"] = campaigns
    pooled_check = campaign_pit_check(campaigns)
    return records, [] if pooled_check is None else [pooled_check]


def calibration_record(
    names: Sequence[str], draws: np.ndarray, scales: np.ndarray
) -> list[dict[str, Any]]:
    """The summary's ``calibration_effects``: per group its ``name``, ``prior_sd`` σ_cal,
    posterior ``median``/``lo95``/``hi95`` [ln R], ``sd`` and ``sd_ratio`` (module
    docstring). ``draws``: (draws, groups) of κ; ``scales``: σ_cal of each group."""
    record = []
    for k, name in enumerate(names):
        values, prior = np.asarray(draws[:, k], float), float(scales[k])
        sd = float(np.std(values))
        record.append(
            {
                "name": str(name),
                "prior_sd": prior,
                **interval95(values),
                "sd": sd,
                "sd_ratio": sd / prior if prior > 0 else None,
            }
        )
    return record


def campaigns_record(
    scene: Scene, measurements: Measurements, elpd_i: np.ndarray, pit: np.ndarray
) -> dict[str, Any] | None:
    """The summary's ``campaigns`` (module docstring); None for a scene of one file."""
    if not scene.campaigns:
        return None
    owner = row_campaigns(measurements)
    record = {}
    for campaign in scene.campaigns:
        rows = owner == campaign.name
        terms = np.asarray(elpd_i, float)[rows]
        record[campaign.name] = {
            "measurements": str(campaign.measurements_path),
            "rows": int(rows.sum()),
            "samples": sorted({str(s) for s in measurements.sample[rows]}),
            "errors": dict(scene.errors.campaign_errors[campaign.name]),
            "elpd_loo": float(terms.sum()),
            "se": float(np.sqrt(terms.size) * np.std(terms)) if terms.size > 1 else None,
            "loo_pit_ks_p": uniformity_p_value(np.asarray(pit)[rows]),
        }
    return record


def campaign_pit_check(campaigns: dict[str, Any]):
    """The ``loo_pit_campaigns`` check of a pooled scene (module docstring) from its
    ``campaigns`` record (:func:`campaigns_record`); None for fewer than two campaigns."""
    if len(campaigns) < 2:
        return None
    p_values = {name: entry["loo_pit_ks_p"] for name, entry in campaigns.items()}
    worst = min(p_values, key=p_values.get)
    p = min(1.0, len(p_values) * p_values[worst])
    ok = p >= CHECK_P_VALUE
    smallest = min(entry["rows"] for entry in campaigns.values())
    spread = detectable_spread(smallest)
    detectable = (
        f"a campaign whose rows scatter {spread:.2g} times the predictive sd (the smallest "
        "campaign's, at one test's level)"
        if np.isfinite(spread)
        else "nothing: too few rows in a campaign"
    )
    if ok:
        words = (
            "every campaign's rows follow the pooled predictive (LOO-PIT uniform within "
            f"chance in each; the least, {worst}, p = {p:.2g} after {len(p_values)} tests)"
        )
    else:
        words = (
            f"campaign {worst}'s rows do not follow the pooled predictive (LOO-PIT p = {p:.2g} "
            f"< {CHECK_P_VALUE:g} after {len(p_values)} tests): its calibration, noise or "
            "coating differ from the others' more than the model allows"
        )
    return check("loo_pit_campaigns", None, p, ok, words, detectable)
