"""The bundled data under each instrument model, side by side (docs/instruments.md).

For every instrument model the scene's geometry supports (``point``, Eq. 6 as in the article;
``aperture``; ``image``), one NUTS posterior on the same rows and error model: BRDF0, α,
TIS(70°) and π·BRDF0 with 95 % intervals, PSIS-LOO (the run's own, from its summary: exact by
refit where the run refitted a row), and the ray tracer's series at a thinned
set of the posterior's draws against the measured values (the Fig. 14 comparison: the paper
compared the Eq. (2) image ratio, ``image_ratio``; ``simulated`` is dPs/Pi through AD).
Written as ``instruments.json`` in a run folder; the report shows it.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from brdf_infer._internal import arviz as az
from brdf_infer.errors import BadInputError
from brdf_infer.instrument import INSTRUMENT_MODELS
from brdf_infer.posterior import interval95
from brdf_infer.runs.folder import INSTRUMENT_FILE as INSTRUMENT_FILE  # the old name, kept
from brdf_infer.runs.folder import RunFolder
from brdf_infer.runs.records import PosteriorSummary
from brdf_infer.scene import Scene, check_instrument
from brdf_infer.tables.measurements import Measurements

TRACE_DRAWS = 16
TRACE_RAYS = 16_384  # per draw and configuration (NEE)


def supported_instruments(scene: Scene) -> list[str]:
    """The instrument models the scene's geometry supports, in :data:`INSTRUMENT_MODELS`
    order."""
    supported = []
    for name in INSTRUMENT_MODELS:
        try:
            check_instrument(scene, name)
        except BadInputError:
            continue
        supported.append(name)
    return supported


def instrument_entry(
    name: str, run_dir: Path, idata: az.InferenceData, summary: PosteriorSummary
) -> dict:
    """One row of the side-by-side table from a ``strumik2024`` posterior run: its elpd_loo
    and se those of the run's PSIS-LOO (``summary["predictive"]``,
    :func:`brdf_infer.posterior.psis_loo`), which also serves a large table's run, whose
    posterior.nc keeps no pointwise terms."""
    posterior = idata.posterior
    loo = summary["predictive"]
    return {
        "instrument": name,
        "run": str(run_dir),
        "brdf0": interval95(posterior["brdf0"]),
        "alpha": interval95(posterior["alpha"]),
        "tis_70deg": summary["tis_70deg"],
        "pi_brdf0": summary["pi_brdf0"],
        "elpd_loo": float(loo["elpd_loo"]),
        "elpd_se": float(loo["se"]),
        "divergences": summary["diagnostics"]["divergences"],
        "r_hat_max": summary["diagnostics"]["r_hat_max"],
    }


def traced_agreement(payload: dict) -> dict[str, float]:
    """RMS of ln(traced/measured) over a ray-traced series: ``image_ratio`` (the paper's
    Fig. 14 quantity) and ``simulated`` (dPs/Pi)."""
    rows = payload["rows"]
    measured = np.array([r["measured"] for r in rows])
    result = {}
    for key in ("image_ratio", "simulated"):
        traced = np.array([r[key] for r in rows])
        ok = (traced > 0) & (measured > 0)
        result[f"rms_ln_{key}"] = float(np.sqrt(np.mean(np.log(traced[ok] / measured[ok]) ** 2)))
    return result


def compare_instruments(
    scene: Scene,
    measurements: Measurements,
    out: Path,
    options: dict[str, Any],
    *,
    instruments: list[str] | None = None,
    done: dict[str, tuple[Path, Any]] | None = None,
    progress: Callable[[str], None] = lambda message: None,
) -> dict[str, Any]:
    """Posteriors under every supported instrument model and their ray-traced series.

    Args:
        scene: a ``strumik2024`` scene.
        measurements: its rows.
        out: the run folder; posteriors not in ``done`` go to ``out/variants/instrument-NAME``.
        options: keyword arguments of :func:`brdf_infer.posterior.run_posterior`.
        instruments: the instrument models (default: every one the scene supports).
        done: posterior runs already made, by instrument model: (folder, PosteriorRun).
        progress: called with one line per step.

    Returns:
        ``{"models": [entry per instrument], "series": traced series}`` (entries of
        :func:`instrument_entry` with ``"raytrace"``: :func:`traced_agreement` and the rows).
    """
    from brdf_infer.posterior import draws_params, run_posterior
    from brdf_infer.studies.raytrace import raytrace_posterior_payload, thin_draws

    done = dict(done or {})
    models = []
    for name in supported_instruments(scene) if instruments is None else instruments:
        if name in done:
            folder, run = done[name]
        else:
            progress(f"  posterior with the '{name}' instrument model")
            folder = RunFolder(out).variant(f"instrument-{name}").path
            run = run_posterior(  # no refits of error-model variants for a study's posterior
                check_instrument(scene, name), measurements, out=folder, refit=False, **options
            )
        entry = instrument_entry(name, folder, run.idata, run.summary)
        if scene.raytrace is not None:
            draws = thin_draws(draws_params(run.idata.posterior), TRACE_DRAWS)
            payload = raytrace_posterior_payload(
                scene, measurements, draws, f"posterior ({name})", rays=TRACE_RAYS
            )
            entry["raytrace"] = {**traced_agreement(payload), "rows": payload["rows"]}
        models.append(entry)
    return {
        "models": models,
        "series": None if scene.raytrace is None else scene.raytrace.series,
        "draws_traced": TRACE_DRAWS,
        "rays": TRACE_RAYS,
    }
