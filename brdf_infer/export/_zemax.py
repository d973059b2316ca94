"""Zemax tabular .BSDF files of a parameter set or of a posterior run: the tables, their TIS
lines and comments, the posterior's pointwise quantiles and single draws (the module docstring
of :mod:`._files` says what each file means)."""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer.bsdf_file import BSDF_SOURCE, BsdfFile, specular_frame_to_model, write_bsdf
from brdf_infer.export._grid import ScatterGrid, brdf_table, table_integral
from brdf_infer.export._source import _BAND_QUANTILES, Source, draw_indices
from brdf_infer.model import ModelFamily, fold_statement, strumik_family, tis
from brdf_infer.params import Params, params_to_dict
from brdf_infer.posterior import FAMILY_TIS_DRAWS, tis_band

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


_TIS_KEYS = {"lower95": "lo95", "median": "median", "upper95": "hi95"}


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
    member = strumik_family(source.fold, source.constants)
    band = tis_band(member, source.params._asdict(), theta_i, FAMILY_TIS_DRAWS)
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
    band = tis_band(member, source.physical, theta_i, FAMILY_TIS_DRAWS)
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
