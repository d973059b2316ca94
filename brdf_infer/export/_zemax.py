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
from brdf_infer.export._grid import ScatterGrid, table_integral
from brdf_infer.export._source import _BAND_QUANTILES, Source, draw_indices
from brdf_infer.model import ModelFamily, Physical, family, fold_statement
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


def _parameter_text(physical: dict[str, float]) -> str:
    return ", ".join(f"{name}={value:.10g}" for name, value in physical.items())


def _comments(source: Source, kind: str, grid: ScatterGrid, extra: list[str]) -> list[str]:
    from brdf_infer import __version__

    member = source.family
    lines = [
        f"brdf_infer {__version__} export, {dt.datetime.now(dt.UTC).isoformat(timespec='seconds')}",
        f"scene: {source.scene}",
        f"source: {'posterior run ' if source.from_run else 'parameter set '}{source.label}",
        f"file: {kind}: "
        + (
            _MEANING[kind]
            if member.paper_parameters
            else _MEANING[kind].replace("exact Eq. (9)", f"{member.name}")
        ),
        (
            "model: Strumik et al. 2024 Eqs. (7), (8)"
            + (", (10)" if source.fold else "")
            + f"; constants {dict(source.constants._asdict())}"
            if member.paper_parameters
            else f"model: {member.name} ("
            + ", ".join(
                f"{n} [{member.units[n].replace('sr⁻¹', '1/sr')}]" for n in member.parameters
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


def export_zemax(
    source: Source,
    grid: ScatterGrid,
    out: Path,
    draws: int = 0,
    progress: Callable[[str], None] = lambda message: None,
) -> list[dict]:
    """Write the .BSDF files of ``source`` (module docstring) into ``out``, for every family.

    Returns:
        One entry per file: path, kind, theta_i_deg, tis, table_integral.
    """
    member, theta_i = source.family, grid.theta_i_deg
    tables = _table_program(member)
    if not source.from_run:
        one = {name: float(value) for name, value in source.physical.items()}
        return [
            _write_table_file(
                out,
                "params.bsdf",
                "params",
                source,
                grid,
                _family_tables(tables, grid, one),
                _tis_lines(member, theta_i, one),
                [f"parameters: {_parameter_text(one)}"],
            )
        ]
    progress(f"TIS band of {member.name} over the draws")
    band = tis_band(member, source.physical, theta_i, FAMILY_TIS_DRAWS)
    quantiles = np.empty(
        (len(_BAND_QUANTILES), theta_i.size, grid.azimuth_deg.size, grid.radial_deg.size)
    )
    for k, t in enumerate(theta_i):
        progress(f"posterior quantiles of the tables at theta_i = {t:g} deg")
        one_angle = ScatterGrid(np.array([t]), grid.azimuth_deg, grid.radial_deg)
        table = _family_tables(tables, one_angle, source.physical)[:, 0]
        quantiles[:, k] = np.quantile(table, list(_BAND_QUANTILES.values()), axis=0)
    thinned = f" (TIS over {band['draws']})" if "draws" in band else ""  # not every draw
    files = _band_files(out, source, grid, quantiles, band, thinned)
    for k, index in enumerate(draw_indices(source.count, draws) if draws else []):
        one = {name: float(np.asarray(values)[index]) for name, values in source.physical.items()}
        progress(f"draw {k + 1} of {draws}")
        files.append(
            _write_table_file(
                out,
                f"draw_{k:03d}.bsdf",
                "draw",
                source,
                grid,
                _family_tables(tables, grid, one),
                _tis_lines(member, theta_i, one),
                [f"posterior draw {index} of {source.count}: {_parameter_text(one)}"],
            )
        )
    return files


def _tis_lines(member: ModelFamily, theta_i: np.ndarray, one: dict[str, float]) -> np.ndarray:
    """TIS(θi) of one parameter set: Eq. (9) at every θi in one call where the family has it
    batched, else the family's TIS per θi."""
    if member.log_tis_draws is not None:
        return np.asarray(jnp.exp(member.log_tis_draws(np.asarray(theta_i, float), one)))
    return np.array([float(member.tis(float(t), one)) for t in theta_i])


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


def _family_tables(one_angle, grid: ScatterGrid, physical: Physical) -> np.ndarray:
    """BRDF tables at every θi by ``one_angle`` (:func:`_table_program`), shape (draws...,
    n_aoi, n_azimuth, n_radial)."""
    psi, r = np.meshgrid(grid.azimuth_deg, grid.radial_deg, indexing="ij")
    batch = {k: jnp.asarray(v, float)[..., None, None] for k, v in physical.items()}
    return np.stack(
        [np.asarray(one_angle(float(t), psi, r, batch)) for t in grid.theta_i_deg], axis=-3
    )


def _table_program(member: ModelFamily):
    """The compiled BRDF table of ``member`` at one θi (angle, parameters and Eq. (10)'s
    constants arguments: one compilation per shape serves every draw and angle of an
    export)."""
    name, fold = member.name, member.fold

    @jax.jit
    def one_angle(theta_i_deg, psi, r, batch, constants):
        inner = family(name, fold, constants)
        theta, phi, z = specular_frame_to_model(theta_i_deg, psi, r)
        return jnp.where(z > 0.0, jnp.exp(inner.log_brdf(theta_i_deg, theta, phi, batch)), 0.0)

    return lambda theta_i_deg, psi, r, batch: one_angle(
        theta_i_deg, psi, r, batch, member.constants
    )
