"""Export a parameter set or a posterior run as Zemax .BSDF tables or ABg fits.

What each file means:

- ``params.bsdf``: the BRDF of one parameter set; TIS lines are its exact Eq. (9) TIS.
- ``median.bsdf``: the pointwise posterior median of the BRDF; TIS lines are the posterior
  median of the TIS at that angle of incidence.
- ``lower95.bsdf`` / ``upper95.bsdf``: the pointwise 2.5 % / 97.5 % posterior quantiles;
  TIS lines are the 2.5 % / 97.5 % quantiles of the TIS. ``upper95.bsdf`` is the
  conservative choice for a stray-light budget (the ray tracer takes the scattered power
  from the TIS line and the angular shape from the table).
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
"""

from __future__ import annotations

import csv
import datetime as dt
import io
import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer._atomic import atomic_write_bytes, atomic_write_json
from brdf_infer._outlock import writing
from brdf_infer.bsdf_file import BSDF_SOURCE, BsdfFile, specular_frame_to_model, write_bsdf
from brdf_infer.errors import BadInputError
from brdf_infer.export._abg import AbgFit, fit_abg
from brdf_infer.export._grid import ScatterGrid, brdf_table, table_integral
from brdf_infer.model import ModelFamily, fold_statement, tis
from brdf_infer.params import HemisphereConstants, Params, params_to_dict
from brdf_infer.posterior import FAMILY_TIS_DRAWS, family_tis_band, tis_band

EXPORTS_FILE = "exports.json"  # in a run folder: the exports made from it, for the report
ABG_COLUMNS = ("theta_i_deg", "A", "B", "g", "tis_model", "tis_abg", "rms_log_error")
_MEANING = {
    "params": "BRDF of one parameter set; TIS lines: its exact Eq. (9) TIS",
    "median": "pointwise posterior median of the BRDF; TIS lines: posterior median TIS",
    "lower95": "pointwise 2.5 % posterior quantile of the BRDF; TIS lines: 2.5 % TIS quantile",
    "upper95": (
        "pointwise 97.5 % posterior quantile of the BRDF; TIS lines: 97.5 % TIS quantile "
        "(the conservative choice for a stray-light budget)"
    ),
    "draw": "one posterior draw: a consistent BRDF with its own exact Eq. (9) TIS",
}
_BAND_QUANTILES = {"lower95": 0.025, "median": 0.5, "upper95": 0.975}
_TIS_KEYS = {"lower95": "lo95", "median": "median", "upper95": "hi95"}


@dataclass(frozen=True)
class Source:
    """Where the exported BRDF comes from.

    Attributes:
        label: the parameter set's name or the run folder, for the file comments.
        params: one parameter set (scalar fields) or every posterior draw (1-D fields).
        from_run: ``params`` holds posterior draws.
        fold: the hemisphere BRDF includes Eq. (10) (the article's Table 3 does; False: the
            physical BRDF; always False with ``family``).
        constants: Δφ and folding constants (None with ``family``).
        scene: the scene's name, for the file comments.
        family: a posterior run of another model family (``params`` is then None and
            ``physical`` holds the draws of its physical parameters).
        physical: the draws of ``family``'s parameters.
    """

    label: str
    params: Params | None
    from_run: bool
    fold: bool
    constants: HemisphereConstants | None
    scene: str
    family: ModelFamily | None = None
    physical: dict[str, np.ndarray] | None = None

    @property
    def count(self) -> int:
        """Number of parameter sets (posterior draws; 1 for a parameter set)."""
        if self.family is not None:
            return int(np.size(next(iter(self.physical.values()))))
        return int(np.size(self.params.brdf0))


def planned_files(source: Source, export_format: str, draws: int) -> list[str]:
    """Names of the files an export writes (checked against ``--force`` before any work)."""
    if export_format == "abg":
        return ["abg.json", "abg.csv"]
    if not source.from_run:
        return ["params.bsdf"]
    bands = [f"{kind}.bsdf" for kind in _BAND_QUANTILES]
    return bands + [f"draw_{k:03d}.bsdf" for k in range(draws)]


def draw_indices(count: int, draws: int) -> np.ndarray:
    """``draws`` evenly spaced indices into ``count`` posterior draws (deterministic)."""
    return np.unique(np.round(np.linspace(0, count - 1, draws)).astype(int))


def _parameter_text(params: Params) -> str:
    return ", ".join(f"{name}={value:.10g}" for name, value in params_to_dict(params).items())


def _comments(source: Source, kind: str, grid: ScatterGrid, extra: list[str]) -> list[str]:
    from brdf_infer import __version__

    lines = [
        f"brdf_infer {__version__} export, {dt.datetime.now(dt.UTC).isoformat(timespec='seconds')}",
        f"scene: {source.scene}",
        f"source: {'posterior run ' if source.from_run else 'parameter set '}{source.label}",
        f"file: {kind}: "
        + (
            _MEANING[kind]
            if source.family is None
            else _MEANING[kind].replace("exact Eq. (9)", f"{source.family.name}")
        ),
        (
            "model: Strumik et al. 2024 Eqs. (7), (8)"
            + (", (10)" if source.fold else "")
            + f"; constants {dict(source.constants._asdict())}"
            if source.family is None
            else f"model: {source.family.name} ("
            + ", ".join(
                f"{n} [{source.family.units[n].replace('sr⁻¹', '1/sr')}]"
                for n in source.family.parameters
            )
            + ")"
        ),
        fold_statement(source.fold),
        f"not measured: the model above evaluated on a grid ('Source {BSDF_SOURCE}' below is "
        "the only Source value the BSDF Data Interchange format defines)",
        "angles in degrees; BSDF in 1/sr; scatter angles relative to the specular ray "
        "(azimuth 0 toward the surface normal); 0 below the horizon",
        f"grid: {grid.theta_i_deg.size} angles of incidence, azimuth step "
        f"{grid.azimuth_deg[1] - grid.azimuth_deg[0]:g}, radial step "
        f"{grid.radial_deg[1] - grid.radial_deg[0]:g}",
    ]
    return lines + extra


def _write_table_file(
    out: Path,
    name: str,
    kind: str,
    source: Source,
    grid: ScatterGrid,
    tables: np.ndarray,
    tis_lines: np.ndarray,
    extra_comments: list[str],
) -> dict:
    integral = np.array(
        [
            table_integral(t, grid.azimuth_deg, grid.radial_deg, table)
            for t, table in zip(grid.theta_i_deg, tables, strict=True)
        ]
    )
    relative = integral / tis_lines - 1.0
    comments = _comments(source, kind, grid, extra_comments)
    comments.append(
        "hemisphere integral of each table vs its TIS line: max |relative difference| "
        f"{np.max(np.abs(relative)):.2e}"
    )
    contents = BsdfFile(
        theta_i_deg=grid.theta_i_deg,
        azimuth_deg=grid.azimuth_deg,
        radial_deg=grid.radial_deg,
        tis=tis_lines[None, :],
        bsdf=tables[None],
        comments=comments,
    )
    path = write_bsdf(out / name, contents)
    return {
        "path": str(path),
        "kind": kind,
        "theta_i_deg": grid.theta_i_deg.tolist(),
        "tis": tis_lines.tolist(),
        "table_integral": integral.tolist(),
    }


def _tables(grid: ScatterGrid, params: Params, source: Source) -> np.ndarray:
    """BRDF tables of one parameter set at every θi: (n_aoi, n_azimuth, n_radial)."""
    return np.stack(
        [
            np.asarray(
                brdf_table(
                    float(t),
                    grid.azimuth_deg,
                    grid.radial_deg,
                    params,
                    source.fold,
                    source.constants,
                )
            )
            for t in grid.theta_i_deg
        ]
    )


def export_zemax(
    source: Source,
    grid: ScatterGrid,
    out: Path,
    draws: int = 0,
    progress: Callable[[str], None] = lambda message: None,
) -> list[dict]:
    """Write the .BSDF files of ``source`` (module docstring) into ``out``.

    Returns:
        One entry per file: path, kind, theta_i_deg, tis, table_integral.
    """
    theta_i = grid.theta_i_deg
    if source.family is not None:
        return _export_family_zemax(source, grid, out, draws, progress)
    if not source.from_run:
        tables = _tables(grid, source.params, source)
        tis_lines = np.asarray(tis(theta_i, source.params, source.fold, source.constants))
        return [
            _write_table_file(
                out,
                "params.bsdf",
                "params",
                source,
                grid,
                tables,
                tis_lines,
                [f"parameters: {_parameter_text(source.params)}"],
            )
        ]
    band = tis_band(source.params, theta_i, source.fold, source.constants)
    quantiles = np.empty(
        (len(_BAND_QUANTILES), theta_i.size, grid.azimuth_deg.size, grid.radial_deg.size)
    )
    for k, t in enumerate(theta_i):
        progress(f"posterior quantiles of the tables at theta_i = {t:g} deg")
        table = np.asarray(
            brdf_table(
                float(t),
                grid.azimuth_deg,
                grid.radial_deg,
                source.params,
                source.fold,
                source.constants,
            )
        )
        quantiles[:, k] = np.quantile(table, list(_BAND_QUANTILES.values()), axis=0)
    count = source.count
    files = _band_files(out, source, grid, quantiles, band, "")
    for k, index in enumerate(draw_indices(count, draws) if draws else []):
        one = Params(*(float(np.asarray(v)[index]) for v in source.params))
        tables = _tables(grid, one, source)
        progress(f"draw {k + 1} of {draws}")
        tis_lines = np.asarray(tis(theta_i, one, source.fold, source.constants))
        files.append(
            _write_table_file(
                out,
                f"draw_{k:03d}.bsdf",
                "draw",
                source,
                grid,
                tables,
                tis_lines,
                [f"posterior draw {index} of {count}: {_parameter_text(one)}"],
            )
        )
    return files


def _band_files(
    out: Path, source: Source, grid: ScatterGrid, quantiles: np.ndarray, band: dict, note: str
) -> list[dict]:
    """``lower95``, ``median`` and ``upper95.bsdf``: the tables' pointwise quantiles
    (``quantiles``, one per file) with the TIS band's quantiles as TIS lines."""
    return [
        _write_table_file(
            out,
            f"{kind}.bsdf",
            kind,
            source,
            grid,
            quantiles[q],
            np.asarray(band[_TIS_KEYS[kind]]),
            [f"quantile {_BAND_QUANTILES[kind]:g} over {source.count} posterior draws{note}"],
        )
        for q, kind in enumerate(_BAND_QUANTILES)
    ]


def _family_tables(member: ModelFamily, grid: ScatterGrid, physical: dict) -> np.ndarray:
    """BRDF tables of ``member`` at every θi, shape (draws..., n_aoi, n_azimuth, n_radial)."""
    psi, r = np.meshgrid(grid.azimuth_deg, grid.radial_deg, indexing="ij")
    batch = {k: jnp.asarray(v, float)[..., None, None] for k, v in physical.items()}

    @jax.jit
    def one_angle(theta_i_deg):
        theta, phi, z = specular_frame_to_model(theta_i_deg, psi, r)
        return jnp.where(z > 0.0, jnp.exp(member.log_brdf(theta_i_deg, theta, phi, batch)), 0.0)

    return np.stack([np.asarray(one_angle(float(t))) for t in grid.theta_i_deg], axis=-3)


def _export_family_zemax(
    source: Source, grid: ScatterGrid, out: Path, draws: int, progress: Callable[[str], None]
) -> list[dict]:
    """:func:`export_zemax` for a run of another model family (module docstring)."""
    member, theta_i = source.family, grid.theta_i_deg
    progress(f"TIS band of {member.name} over at most {FAMILY_TIS_DRAWS} draws")
    band = family_tis_band(member, source.physical, theta_i, FAMILY_TIS_DRAWS)
    quantiles = np.empty(
        (len(_BAND_QUANTILES), theta_i.size, grid.azimuth_deg.size, grid.radial_deg.size)
    )
    for k, t in enumerate(theta_i):
        progress(f"posterior quantiles of the tables at theta_i = {t:g} deg")
        one = ScatterGrid(np.array([t]), grid.azimuth_deg, grid.radial_deg)
        table = _family_tables(member, one, source.physical)[:, 0]
        quantiles[:, k] = np.quantile(table, list(_BAND_QUANTILES.values()), axis=0)
    files = _band_files(out, source, grid, quantiles, band, f" (TIS over {band['draws']})")
    for k, index in enumerate(draw_indices(source.count, draws) if draws else []):
        one = {name: float(values[index]) for name, values in source.physical.items()}
        progress(f"draw {k + 1} of {draws}")
        tis_lines = np.array([float(member.tis(float(t), one)) for t in theta_i])
        text = ", ".join(f"{name}={value:.10g}" for name, value in one.items())
        files.append(
            _write_table_file(
                out,
                f"draw_{k:03d}.bsdf",
                "draw",
                source,
                grid,
                _family_tables(member, grid, one),
                tis_lines,
                [f"posterior draw {index} of {source.count}: {text}"],
            )
        )
    return files


# ---------------------------------------------------------------------------- ABg


def _abg_of_abg_run(source: Source, theta_i: np.ndarray) -> tuple[list[dict], dict]:
    """The ABg rows of a posterior run of ``abg`` itself: its A, B, g (the same at every θi)
    and its TIS, median and 95 % interval over the draws; nothing is fitted.

    Raises:
        BadInputError: a run of a family that ABg cannot represent.
    """
    member = source.family
    if member.name != "abg":
        raise BadInputError(
            f"ABg rows are fitted to Eq. (7) or read from an abg run, not a run of {member.name} "
            "(export it with --format zemax-bsdf)",
            field="format",
        )
    band = family_tis_band(member, source.physical, theta_i, FAMILY_TIS_DRAWS)
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
    if source.family is not None:
        rows, details = _abg_of_abg_run(source, theta_i)
    elif not source.from_run:
        progress("fitting ABg")
        model_tis = np.asarray(tis(theta_i, source.params, source.fold, source.constants))
        rows = _abg_rows(fit_abg(theta_i, source.params, model_tis, source.fold, source.constants))
        details = {"parameters": params_to_dict(source.params)}
    else:
        count = source.count
        median = Params(*(float(np.median(v)) for v in source.params))
        progress("fitting ABg to the posterior median parameters")
        centre = fit_abg(
            theta_i,
            median,
            np.asarray(tis(theta_i, median, source.fold, source.constants)),
            source.fold,
            source.constants,
        )
        fits = []
        for k, index in enumerate(draw_indices(count, draws)):
            progress(f"fitting ABg to draw {k + 1} of {draws}")
            one = Params(*(float(np.asarray(v)[index]) for v in source.params))
            model_tis = np.asarray(tis(theta_i, one, source.fold, source.constants))
            fits.append(fit_abg(theta_i, one, model_tis, source.fold, source.constants, centre))
        rows = _abg_band_rows(fits, theta_i)
        details = {"draws": len(fits), "of_draws": count}
    content = {
        "model": "BSDF = A / (B + |beta - beta0|^g), beta = projection on the surface [-]",
        "fold": source.fold,
        "folding": fold_statement(source.fold),
        "scene": source.scene,
        "source": source.label,
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
) -> dict:
    """Write the export and return the ``brdf-infer export --json`` object (``"fold"``: Eq. 10
    in the exported BRDF)."""
    start = time.perf_counter()
    if export_format == "abg":
        files, rows = export_abg(source, grid.theta_i_deg, out, draws or 100, progress)
        return {
            "format": export_format,
            "fold": source.fold,
            "files": files,
            "rows": rows,
            "seconds": time.perf_counter() - start,
        }
    files = export_zemax(source, grid, out, draws, progress)
    return {
        "format": export_format,
        "fold": source.fold,
        "files": files,
        "seconds": time.perf_counter() - start,
    }


def record_export(run: Path, result: dict) -> Path:
    """Note an export of ``run`` in ``run/exports.json`` (one entry per format and folder), so
    that ``brdf-infer report`` can show it."""
    with writing(run, "export", option="run", adds=True):
        return _record_export(run, result)


def _record_export(run: Path, result: dict) -> Path:
    path = run / EXPORTS_FILE
    try:
        entries = json.loads(path.read_text())["exports"] if path.is_file() else []
    except (OSError, ValueError, KeyError):
        entries = []
    folder = str(Path(result["files"][0]["path"]).parent.resolve())
    entry = {
        "format": result["format"],
        "fold": result["fold"],
        "folder": folder,
        "files": [
            {"path": str(Path(f["path"]).resolve()), "kind": f["kind"]} for f in result["files"]
        ],
        **({"rows": result["rows"]} if "rows" in result else {}),
    }
    keep = [e for e in entries if (e["format"], e["folder"]) != (entry["format"], folder)]
    return atomic_write_json(path, {"exports": [*keep, entry]})
