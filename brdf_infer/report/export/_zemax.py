"""Zemax tabular .BSDF files of a parameter set or of a posterior run: the tables, their TIS
lines and comments, the posterior's pointwise quantiles and single draws (the module docstring
of :mod:`._files` says what each file means)."""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer.model import ModelFamily, Physical, family, fold_statement
from brdf_infer.posterior import FAMILY_TIS_DRAWS, QUANTILES
from brdf_infer.report.export._grid import ScatterGrid, table_integral
from brdf_infer.report.export._source import (
    _BAND_QUANTILES,
    _TIS_QUANTILE_FILES,
    Source,
    draw_indices,
)
from brdf_infer.tables.bsdf_file import BSDF_SOURCE, BsdfFile, specular_frame_to_model, write_bsdf

_ENVELOPE = (
    "a pointwise envelope (each cell's {what} over the draws), no BRDF of any draw, so its "
    "hemisphere integral is not the TIS quantile"
)
_MEANING = {
    "params": "BRDF of one parameter set; TIS lines: its exact Eq. (9) TIS",
    "median": "pointwise posterior median of the BRDF, "
    + _ENVELOPE.format(what="median")
    + "; TIS lines: posterior median TIS (tis_q500.bsdf: the draw at the median TIS)",
    "lower95": "pointwise 2.5 % posterior quantile of the BRDF, "
    + _ENVELOPE.format(what="2.5 % quantile")
    + " (it falls short of it); TIS lines: 2.5 % TIS quantile (tis_q025.bsdf: the draw at "
    "that quantile)",
    "upper95": "pointwise 97.5 % posterior quantile of the BRDF, "
    + _ENVELOPE.format(what="97.5 % quantile")
    + " (it exceeds it); TIS lines: 97.5 % TIS quantile, the conservative envelope for a "
    "stray-light budget (tis_q975.bsdf: the draw at that quantile, a real BRDF)",
    "draw": "one posterior draw: a consistent BRDF with its own exact Eq. (9) TIS",
    "tis_quantile": "the posterior draw at the {percent} % TIS quantile {where}: a real BRDF of "
    "the posterior; TIS lines: that draw's exact Eq. (9) TIS",
}


_TIS_KEYS = {"lower95": "lo95", "median": "median", "upper95": "hi95"}


def _parameter_text(physical: dict[str, float]) -> str:
    return ", ".join(f"{name}={value:.10g}" for name, value in physical.items())


def _comments(
    source: Source, kind: str, grid: ScatterGrid, extra: list[str], meaning: str
) -> list[str]:
    from brdf_infer import __version__

    member = source.family
    lines = [
        f"brdf_infer {__version__} export, {dt.datetime.now(dt.UTC).isoformat(timespec='seconds')}",
        f"scene: {source.scene}",
        f"source: {'posterior run ' if source.from_run else 'parameter set '}{source.label}"
        + (f", target {source.target}" if source.target else ""),
        f"file: {kind}: "
        + (meaning if member.paper_parameters else meaning.replace("exact Eq. (9)", member.name)),
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
    meaning: str | None = None,
    record: dict | None = None,
) -> dict:
    """One .BSDF file and its entry of the JSON (``record``: what else it holds)."""
    integral = np.array(
        [
            table_integral(t, grid.azimuth_deg, grid.radial_deg, table)
            for t, table in zip(grid.theta_i_deg, tables, strict=True)
        ]
    )
    relative = integral / tis_lines - 1.0
    record = {"quadrature_error": np.abs(relative).tolist(), **(record or {})}
    comments = _comments(source, kind, grid, extra_comments, meaning or _MEANING[kind])
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
        **record,
    }


def export_zemax(
    source: Source,
    grid: ScatterGrid,
    out: Path,
    draws: int = 0,
    progress: Callable[[str], None] = lambda message: None,
    tis_quantile_at: float | None = None,
) -> list[dict]:
    """Write the .BSDF files of ``source`` (module docstring) into ``out``, for every family.

    Args:
        tis_quantile_at: the angle of incidence [deg] whose TIS quantiles pick the one draw of
            each ``tis_q*.bsdf`` file; None: each block is the draw at its own angle's quantile.

    Returns:
        One entry per file: path, kind, theta_i_deg, tis, table_integral, quadrature_error
        (|table integral / TIS line − 1| of a real BRDF; of an envelope, that of the draws'
        integrals at its quantile), and for a posterior run grid_quadrature_error (per θi, the
        largest |table integral / TIS − 1| of any draw) and what each file is.
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
    progress(f"TIS of the draws of {member.name}")
    index, tis_draws = _draw_tis(member, source.physical, theta_i)
    ranked = (
        tis_draws
        if tis_quantile_at is None
        else _draw_tis(member, source.physical, np.array([tis_quantile_at]))[1]
    )
    picked = _quantile_positions(ranked, theta_i.size)
    shape = (len(_BAND_QUANTILES), theta_i.size, grid.azimuth_deg.size, grid.radial_deg.size)
    quantiles, chosen = np.empty(shape), np.empty(shape)
    integrals = np.empty(tis_draws.shape)
    for k, t in enumerate(theta_i):
        progress(f"posterior quantiles of the tables at theta_i = {t:g} deg")
        one_angle = ScatterGrid(np.array([t]), grid.azimuth_deg, grid.radial_deg)
        table = _family_tables(tables, one_angle, source.physical)[:, 0]
        quantiles[:, k] = np.quantile(table, list(_BAND_QUANTILES.values()), axis=0)
        candidates = table if index.size == source.count else table[index]
        integrals[:, k] = table_integral(t, grid.azimuth_deg, grid.radial_deg, candidates)
        chosen[:, k] = candidates[picked[:, k]]
    draws_tis = Draws(index, tis_draws, integrals, source.count)
    files = _band_files(out, source, grid, quantiles, draws_tis)
    files += _tis_quantile_files(out, source, grid, chosen, picked, draws_tis, tis_quantile_at)
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
                record={"draw_index": int(index)},
            )
        )
    return files


@dataclass(frozen=True)
class Draws:
    """The TIS of the posterior draws that the TIS quantiles are taken over.

    Attributes:
        index: the draws' indices into the run's draws (every draw where the family's TIS is
            Eq. (9) batched, else :data:`FAMILY_TIS_DRAWS` evenly spaced ones), shape (n,).
        tis: their exact TIS at every θi of the grid, shape (n, n_aoi).
        integral: their tables' hemisphere integrals on the grid, shape (n, n_aoi).
        count: the run's number of draws.
    """

    index: np.ndarray
    tis: np.ndarray
    integral: np.ndarray
    count: int

    @property
    def grid_error(self) -> np.ndarray:
        """Per θi, the largest |table integral / TIS − 1| of any draw: the grid's quadrature
        error for the BRDFs of this posterior."""
        return np.max(np.abs(self.integral / self.tis - 1.0), axis=0)

    @property
    def note(self) -> str:
        thinned = self.index.size < self.count
        return f" (TIS over {self.index.size} evenly spaced draws)" if thinned else ""


def _draw_tis(member: ModelFamily, physical: Physical, theta_i: np.ndarray):
    """(index, TIS): the exact TIS of every draw at every θi where the family has Eq. (9)
    batched, else of :data:`FAMILY_TIS_DRAWS` evenly spaced draws (the draws the TIS band
    of :func:`brdf_infer.posterior.tis_band` is taken over), shape (n, n_aoi)."""
    theta = np.asarray(theta_i, float)
    count = int(np.size(next(iter(physical.values()))))
    if member.log_tis_draws is not None:
        return np.arange(count), np.asarray(jnp.exp(member.log_tis_draws(theta, physical)))
    index = draw_indices(count, FAMILY_TIS_DRAWS)
    thinned = {k: jnp.asarray(np.asarray(v)[index], float) for k, v in physical.items()}

    @jax.jit
    def curve(batch, angles):
        per_draw = jax.vmap(lambda t, one: member.tis(t, one), in_axes=(0, None))
        return jax.lax.map(lambda one: per_draw(angles, one), batch, batch_size=16)

    return index, np.asarray(curve(thinned, jnp.asarray(theta)))


def _quantile_positions(tis: np.ndarray, n_aoi: int) -> np.ndarray:
    """Per TIS quantile (rows: 2.5, 50, 97.5 %) and θi, the position of the draw at that
    quantile: the order statistic of rank round(q (n − 1)) of ``tis`` (n, n_aoi), or of its one
    column (one angle for every θi)."""
    order = np.argsort(tis, axis=0)
    ranks = np.round(np.array(list(_BAND_QUANTILES.values())) * (tis.shape[0] - 1)).astype(int)
    return np.broadcast_to(order[ranks], (ranks.size, n_aoi)).copy()


def _tis_lines(member: ModelFamily, theta_i: np.ndarray, one: dict[str, float]) -> np.ndarray:
    """TIS(θi) of one parameter set: Eq. (9) at every θi in one call where the family has it
    batched, else the family's TIS per θi."""
    if member.log_tis_draws is not None:
        return np.asarray(jnp.exp(member.log_tis_draws(np.asarray(theta_i, float), one)))
    return np.array([float(member.tis(float(t), one)) for t in theta_i])


def _grid_error_comment(draws: Draws) -> str:
    return (
        "grid quadrature error (per angle of incidence, the largest |table integral / TIS - 1| "
        f"of any posterior draw{draws.note}): " + ", ".join(f"{e:.1e}" for e in draws.grid_error)
    )


def _band_files(
    out: Path, source: Source, grid: ScatterGrid, quantiles: np.ndarray, draws: Draws
) -> list[dict]:
    """``lower95``, ``median`` and ``upper95.bsdf``: the tables' pointwise quantiles
    (``quantiles``, one per file), pointwise envelopes, with the TIS quantiles as TIS lines."""
    files = []
    for q, (kind, level) in enumerate(_BAND_QUANTILES.items()):
        tis_lines = np.quantile(draws.tis, QUANTILES[_TIS_KEYS[kind]], axis=0)
        of_integrals = np.quantile(draws.integral, level, axis=0)
        table_integrals = np.array(
            [
                table_integral(t, grid.azimuth_deg, grid.radial_deg, quantiles[q, k])
                for k, t in enumerate(grid.theta_i_deg)
            ]
        )
        excess = table_integrals / of_integrals - 1.0
        record = {
            "pointwise_envelope": True,
            "meaning": _MEANING[kind],
            # the quadrature part of the miss: the draws' integrals at the quantile vs the TIS's
            "quadrature_error": np.abs(of_integrals / tis_lines - 1.0).tolist(),
            "pointwise_excess": excess.tolist(),
            "grid_quadrature_error": draws.grid_error.tolist(),
        }
        files.append(
            _write_table_file(
                out,
                f"{kind}.bsdf",
                kind,
                source,
                grid,
                quantiles[q],
                tis_lines,
                [
                    f"quantile {level:g} over {source.count} posterior draws{draws.note}",
                    "pointwise envelope: its hemisphere integral differs from the "
                    f"{100 * level:g} % quantile of the draws' integrals by "
                    + ", ".join(f"{100 * e:+.1f} %" for e in excess)
                    + " (per angle of incidence)",
                    _grid_error_comment(draws),
                ],
                record=record,
            )
        )
    return files


def _tis_quantile_files(
    out: Path,
    source: Source,
    grid: ScatterGrid,
    chosen: np.ndarray,
    picked: np.ndarray,
    draws: Draws,
    at: float | None,
) -> list[dict]:
    """``tis_q025``, ``tis_q500`` and ``tis_q975.bsdf``: per θi the table of the draw at that
    TIS quantile (``chosen``, positions ``picked`` among ``draws``), TIS lines its own TIS."""
    where = (
        "at each angle of incidence (each block the draw at its own angle's quantile)"
        if at is None
        else f"at theta_i = {at:g} deg (one draw for every block)"
    )
    columns = np.arange(grid.theta_i_deg.size)
    files = []
    for q, (name, band_kind) in enumerate(_TIS_QUANTILE_FILES.items()):
        level = _BAND_QUANTILES[band_kind]
        positions = picked[q]
        tis_lines = draws.tis[positions, columns]
        index = draws.index[positions]
        lines = [
            f"angle of incidence {t:g} deg: posterior draw {index[k]} of {draws.count}{draws.note}"
            f", TIS {tis_lines[k]:.6g}"
            for k, t in enumerate(grid.theta_i_deg)
        ]
        lines += [
            f"draw {i}: "
            + _parameter_text({n: float(np.asarray(v)[i]) for n, v in source.physical.items()})
            for i in np.unique(index)
        ]
        lines.append(_grid_error_comment(draws))
        meaning = _MEANING["tis_quantile"].format(percent=f"{100 * level:g}", where=where)
        record = {
            "pointwise_envelope": False,
            "meaning": meaning,
            "quantile": level,
            "tis_quantile_at_deg": at,
            "draw_index": index.tolist(),
            "tis_band_quantile": np.quantile(draws.tis, level, axis=0).tolist(),
            "grid_quadrature_error": draws.grid_error.tolist(),
        }
        files.append(
            _write_table_file(
                out,
                f"{name}.bsdf",
                name,
                source,
                grid,
                chosen[q],
                tis_lines,
                lines,
                meaning,
                record,
            )
        )
    return files


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
    name, fold, dphi_free = member.name, member.fold, member.dphi_free

    @jax.jit
    def one_angle(theta_i_deg, psi, r, batch, constants):
        inner = family(name, fold, constants, dphi_free)  # each draw's own Δφ where free
        theta, phi, z = specular_frame_to_model(theta_i_deg, psi, r)
        return jnp.where(z > 0.0, jnp.exp(inner.log_brdf(theta_i_deg, theta, phi, batch)), 0.0)

    return lambda theta_i_deg, psi, r, batch: one_angle(
        theta_i_deg, psi, r, batch, member.constants
    )
