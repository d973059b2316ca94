"""Export a parameter set or a posterior run as Zemax .BSDF tables or ABg fits.

What each file means:

- ``params.bsdf``: the BRDF of one parameter set; TIS lines are its exact Eq. (9) TIS.
- ``tis_q025.bsdf`` / ``tis_q500.bsdf`` / ``tis_q975.bsdf``: the posterior draw whose TIS
  is at the 2.5 % / 50 % / 97.5 % TIS quantile, at each angle of incidence (each block the draw
  at its own angle's quantile) or at one angle (``tis_quantile_at``: one draw for every block);
  real BRDFs of the posterior, TIS lines their own exact TIS, so each table integrates to its
  TIS line within the grid's quadrature error. ``tis_q975.bsdf`` is the bound for a
  conservative stray-light budget.
- ``median.bsdf``: the pointwise posterior median of the BRDF; TIS lines are the posterior
  median of the TIS at that angle of incidence.
- ``lower95.bsdf`` / ``upper95.bsdf``: the pointwise 2.5 % / 97.5 % posterior quantiles;
  TIS lines are the 2.5 % / 97.5 % quantiles of the TIS (the ray tracer takes the scattered
  power from the TIS line and the angular shape from the table). These three are pointwise
  envelopes, no BRDF of any draw: their hemisphere integrals are not the TIS quantiles (their
  comments, ``"pointwise_envelope"`` and ``"pointwise_excess"`` in the JSON say so and by how
  much).
- ``draw_000.bsdf`` …: single posterior draws, each a consistent BRDF with its own exact TIS,
  for Monte Carlo stray-light runs (the spread of their results is the budget's band).
- ``abg.json`` / ``abg.csv``: TIS-preserving ABg fits per angle of incidence.

A posterior run of another model family (``abg``, ``harvey-shack``, ``lambertian``,
``lambertian+abg``) exports the same .BSDF files from that family's BRDF and TIS (the TIS lines
of a band from at most 400 evenly spaced draws, each TIS a 2-D quadrature); a run of ``abg``
exports its own posterior A, B, g as the ABg rows.

Every export says whether Eq. (10)'s folding is in it (a comment line of each .BSDF file,
``"fold"`` in ``abg.json`` and in the returned JSON): by default it is not (the physical BRDF,
conservative for a stray-light budget); a run's export follows its scene's ``[model] fold``.
The .BSDF ``Source`` keyword reads ``Measured``, the only value the BSDF Data Interchange format
defines; a comment line says that the tables are a model evaluated on a grid.

The .BSDF files are written by :mod:`._zemax`, from a :class:`._source.Source`; the ABg fits
here.
"""

from __future__ import annotations

import csv
import io
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from brdf_infer._internal.atomic import atomic_write_bytes, atomic_write_json
from brdf_infer._internal.outlock import writing
from brdf_infer.errors import BadInputError
from brdf_infer.model import fold_statement, tis
from brdf_infer.model.params import Params, params_to_dict
from brdf_infer.posterior import FAMILY_TIS_DRAWS, tis_band
from brdf_infer.report.export._abg import AbgFit, fit_abg
from brdf_infer.report.export._grid import ScatterGrid
from brdf_infer.report.export._source import Source, draw_indices
from brdf_infer.report.export._zemax import export_zemax
from brdf_infer.runs.folder import RunFolder

ABG_COLUMNS = ("theta_i_deg", "A", "B", "g", "tis_model", "tis_abg", "rms_log_error")


# ---------------------------------------------------------------------------- ABg


def _abg_of_abg_run(source: Source, theta_i: np.ndarray) -> tuple[list[dict], dict]:
    """The ABg rows of a posterior run of ``abg`` itself: its A, B, g (the same at every θi)
    and its TIS, median and 95 % interval over the draws; nothing is fitted.

    Raises:
        BadInputError: a run of a family that ABg cannot represent.
    """
    member = source.family
    if not member.abg_parameters:
        raise BadInputError(
            f"ABg rows are fitted to Eq. (7) or read from an abg run, not a run of {member.name} "
            "(export it with --format zemax-bsdf)",
            field="format",
        )
    band = tis_band(member, source.physical, theta_i, FAMILY_TIS_DRAWS)
    columns = {name: np.quantile(source.physical[name], [0.025, 0.5, 0.975]) for name in "ABg"}
    rows = []
    for k, t in enumerate(theta_i):
        row = {"theta_i_deg": float(t)}
        for name, (low, median, high) in columns.items():
            row |= {name: float(median), f"{name}_lo95": float(low), f"{name}_hi95": float(high)}
        for name in ("tis_model", "tis_abg"):
            row |= {
                name: band["median"][k],
                f"{name}_lo95": band["lo95"][k],
                f"{name}_hi95": band["hi95"][k],
            }
        row |= {"rms_log_error": 0.0, "rms_log_error_lo95": 0.0, "rms_log_error_hi95": 0.0}
        rows.append(row)
    return rows, {"draws": source.count, "of_draws": source.count, "fitted": False}


# ---------------------------------------------------------------------------- ABg fits


def _abg_rows(fit: AbgFit) -> list[dict]:
    return [
        {
            "theta_i_deg": float(fit.theta_i_deg[k]),
            "A": float(fit.a[k]),
            "B": float(fit.b[k]),
            "g": float(fit.g[k]),
            "tis_model": float(fit.tis_model[k]),
            "tis_abg": float(fit.tis_abg[k]),
            "rms_log_error": float(fit.rms_log_error[k]),
        }
        for k in range(fit.theta_i_deg.size)
    ]


def _abg_band_rows(fits: list[AbgFit], theta_i: np.ndarray) -> list[dict]:
    """Median and 95 % interval of every column over the draws' fits."""
    stacked = {
        "A": np.stack([f.a for f in fits]),
        "B": np.stack([f.b for f in fits]),
        "g": np.stack([f.g for f in fits]),
        "tis_model": np.stack([f.tis_model for f in fits]),
        "tis_abg": np.stack([f.tis_abg for f in fits]),
        "rms_log_error": np.stack([f.rms_log_error for f in fits]),
    }
    rows = []
    for k, t in enumerate(theta_i):
        row = {"theta_i_deg": float(t)}
        for name, values in stacked.items():
            low, median, high = np.quantile(values[:, k], [0.025, 0.5, 0.975])
            row |= {name: float(median), f"{name}_lo95": float(low), f"{name}_hi95": float(high)}
        rows.append(row)
    return rows


def _csv_text(rows: list[dict]) -> str:
    stream = io.StringIO()
    writer = csv.DictWriter(stream, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: f"{v:.10g}" for k, v in row.items()})
    return stream.getvalue()


def export_abg(
    source: Source,
    theta_i_deg: np.ndarray,
    out: Path,
    draws: int = 100,
    progress: Callable[[str], None] = lambda message: None,
) -> tuple[list[dict], list[dict]]:
    """Fit ABg per θi (TIS preserved) and write ``abg.json`` and ``abg.csv``.

    With a run, each of ``draws`` evenly spaced posterior draws is fitted (starting from the
    fit of the posterior median parameters) and the rows hold the median and the 95 % interval.

    Returns:
        (files, rows).
    """
    theta_i = np.asarray(theta_i_deg, float)
    if not source.family.paper_parameters:  # an abg run's own rows (others are refused)
        rows, details = _abg_of_abg_run(source, theta_i)
    elif not source.from_run:
        progress("fitting ABg")
        model_tis = np.asarray(tis(theta_i, source.params, source.fold, source.constants))
        rows = _abg_rows(fit_abg(theta_i, source.params, model_tis, source.fold, source.constants))
        details = {"parameters": params_to_dict(source.params)}
    else:
        count = source.count
        median = Params(*(float(np.median(v)) for v in source.params))
        # Eq. (8)'s constants of the median and of each draw: its own out-of-plane width
        middle = source.family.constants_of(
            {name: float(np.median(v)) for name, v in source.physical.items()}
        )
        progress("fitting ABg to the posterior median parameters")
        centre = fit_abg(
            theta_i,
            median,
            np.asarray(tis(theta_i, median, source.fold, middle)),
            source.fold,
            middle,
        )
        fits = []
        for k, index in enumerate(draw_indices(count, draws)):
            progress(f"fitting ABg to draw {k + 1} of {draws}")
            one = Params(*(float(np.asarray(v)[index]) for v in source.params))
            own = source.family.constants_of(
                {name: float(np.asarray(v)[index]) for name, v in source.physical.items()}
            )
            model_tis = np.asarray(tis(theta_i, one, source.fold, own))
            fits.append(fit_abg(theta_i, one, model_tis, source.fold, own, centre))
        rows = _abg_band_rows(fits, theta_i)
        details = {"draws": len(fits), "of_draws": count}
    content = {
        "model": "BSDF = A / (B + |beta - beta0|^g), beta = projection on the surface [-]",
        "fold": source.fold,
        "folding": fold_statement(source.fold),
        "scene": source.scene,
        "source": source.label,
        "target": source.target or None,
        **details,
        "rows": rows,
    }
    files = [
        {"path": str(atomic_write_json(out / "abg.json", content)), "kind": "abg"},
        {"path": str(atomic_write_bytes(out / "abg.csv", _csv_text(rows).encode())), "kind": "abg"},
    ]
    return files, rows


def run_export(
    source: Source,
    export_format: str,
    grid: ScatterGrid,
    out: Path,
    draws: int = 0,
    progress: Callable[[str], None] = lambda message: None,
    tis_quantile_at: float | None = None,
) -> dict:
    """Write the export and return the ``brdf-infer export --json`` object (``"fold"``: Eq. 10
    in the exported BRDF; ``tis_quantile_at``: :func:`._zemax.export_zemax`)."""
    start = time.perf_counter()
    if export_format == "abg":
        files, rows = export_abg(source, grid.theta_i_deg, out, draws or 100, progress)
        return {
            "format": export_format,
            "fold": source.fold,
            **({"target": source.target} if source.from_run else {}),
            "files": files,
            "rows": rows,
            "seconds": time.perf_counter() - start,
        }
    files = export_zemax(source, grid, out, draws, progress, tis_quantile_at)
    return {
        "format": export_format,
        "fold": source.fold,
        **({"target": source.target} if source.from_run else {}),
        **({"tis_quantile_at_deg": tis_quantile_at} if source.from_run else {}),
        "files": files,
        "seconds": time.perf_counter() - start,
    }


def record_export(run: Path, result: dict) -> Path:
    """Note an export of ``run`` in ``run/exports.json`` (one entry per format and folder), so
    that ``brdf-infer report`` can show it."""
    with writing(run, "export", option="run", adds=True):
        return _record_export(run, result)


def _record_export(run: Path, result: dict) -> Path:
    entries = RunFolder(run).exports()
    folder = str(Path(result["files"][0]["path"]).parent.resolve())
    entry = {
        "format": result["format"],
        "fold": result["fold"],
        **({"target": result["target"]} if "target" in result else {}),
        "folder": folder,
        "files": [
            {"path": str(Path(f["path"]).resolve()), "kind": f["kind"]} for f in result["files"]
        ],
        **({"rows": result["rows"]} if "rows" in result else {}),
    }
    keep = [e for e in entries if (e["format"], e["folder"]) != (entry["format"], folder)]
    return RunFolder(run).write_exports([*keep, entry])
