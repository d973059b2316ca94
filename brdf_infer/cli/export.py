"""``brdf-infer export``: Zemax ``.BSDF`` tables or ABg rows of a parameter set or a posterior
run (:mod:`brdf_infer.report.export`), every option checked before any work; ``--check`` reads a
``.BSDF`` file back."""

from __future__ import annotations

import argparse
import contextlib
from pathlib import Path

import numpy as np

from brdf_infer._internal.outlock import writing
from brdf_infer.cli._common import emit_json, progress, scene_command_parser, table
from brdf_infer.cli._options import (
    add_fold_arguments,
    add_run_target_arguments,
    angles,
    checked_run_target,
    chosen_fold,
    folded_family,
)
from brdf_infer.cli._outdir import check_output_dir
from brdf_infer.errors import BadInputError

MAX_INTEGRAL_ERROR = 0.01  # a table whose own hemisphere integral misses its TIS by more
_TWINS = {"lower95": "tis_q025", "median": "tis_q500", "upper95": "tis_q975"}
_WHAT = {"lower95": "2.5 % quantile", "median": "median", "upper95": "97.5 % quantile"}


def add_parser(commands) -> argparse.ArgumentParser:
    """The options of ``brdf-infer export``."""
    parser = scene_command_parser(
        commands, "export", "Zemax .BSDF tables or ABg fits of a parameter set or a posterior run"
    )
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--params", help="parameter set name (uv-paper, vis-paper) or JSON file")
    source.add_argument("--run", help="posterior run directory: median, 95 %% bounds and draws")
    source.add_argument(
        "--check", metavar="FILE", help="read a .BSDF file and compare each table with its TIS"
    )
    parser.add_argument("--format", choices=["zemax-bsdf", "abg"], default="zemax-bsdf")
    parser.add_argument("--out", help="output directory (required unless --check)")
    parser.add_argument(
        "--theta-i", type=float, nargs="+", help="angles of incidence [deg] (default 0, 5, …, 85)"
    )
    parser.add_argument("--azimuth-step", type=float, default=5.0, help="scatter azimuth [deg]")
    parser.add_argument("--radial-step", type=float, default=1.0, help="scatter radial [deg]")
    parser.add_argument(
        "--draws",
        type=int,
        default=0,
        help="--run: also write this many single-draw .BSDF files (abg: draws fitted, 100)",
    )
    parser.add_argument(
        "--tis-quantile-at",
        type=float,
        metavar="DEG",
        help="--run: the tis_q025/q500/q975.bsdf tables are the draws at the TIS quantiles at "
        "this angle of incidence, one draw per file (default: at each angle of incidence, "
        "each block the draw at its own angle's quantile)",
    )
    add_fold_arguments(parser, "the scene's or the run's [model] fold, false unless set")
    add_run_target_arguments(parser)
    parser.add_argument("--force", action="store_true", help="overwrite existing output files")
    parser.set_defaults(handler=main)
    return parser


def _checked_options(args: argparse.Namespace) -> None:
    if not 0.0 < args.azimuth_step <= 45.0:
        raise BadInputError(f"{args.azimuth_step:g} is outside (0, 45] deg", field="--azimuth-step")
    if not 0.0 < args.radial_step <= 10.0:
        raise BadInputError(f"{args.radial_step:g} is outside (0, 10] deg", field="--radial-step")
    if args.draws < 0:
        raise BadInputError(f"{args.draws} is negative", field="--draws")
    if args.draws and args.run is None:
        raise BadInputError("single draws need a posterior (--run)", field="--draws")
    if args.tis_quantile_at is not None:
        if args.run is None or args.format != "zemax-bsdf":
            raise BadInputError(
                "TIS-quantile tables are of a posterior's .BSDF export (--run, zemax-bsdf)",
                field="--tis-quantile-at",
            )
        angles([args.tis_quantile_at], "--tis-quantile-at", 0.0, 90.0, upper_open=True)
    if args.out is None:
        raise BadInputError("an output directory is required", field="--out")


def _source(args: argparse.Namespace, scene_name: str):
    from brdf_infer.model import strumik_family
    from brdf_infer.model.params import params_to_dict, resolve_params
    from brdf_infer.posterior import load_run_target
    from brdf_infer.report.export import Source
    from brdf_infer.runs.folder import RunFolder

    if args.run is not None:
        run = Path(args.run)
        member, physical, target = load_run_target(run, args.target, args.sample)
        member = folded_family(member, args.fold)
        with contextlib.suppress(OSError, ValueError, KeyError):
            scene_name = RunFolder(run).summary()["scene"]
        if args.format == "abg" and not (member.paper_parameters or member.abg_parameters):
            raise BadInputError(
                f"ABg rows are fitted to Eq. (7) or read from an abg run, not a run of "
                f"{member.name} (export it with --format zemax-bsdf)",
                field="--format",
            )
        which = f"sample {args.sample}" if args.sample else target
        return Source(str(run), member, physical, True, scene_name, which)
    from brdf_infer.scene import load_scene

    scene = load_scene(scene_name)
    member = strumik_family(chosen_fold(args.fold, scene.outputs.fold), scene.model.constants)
    physical = params_to_dict(resolve_params(args.params))
    return Source(args.params, member, physical, False, scene.name)


def main(args: argparse.Namespace) -> int:
    """Export (nothing written on bad input) and print what was written."""
    from brdf_infer.report.export import (
        DEFAULT_THETA_I_DEG,
        planned_files,
        record_export,
        run_export,
        scatter_grid,
    )

    if args.check is not None:
        _check_file(Path(args.check), args.json)
        return 0
    _checked_options(args)
    checked_run_target(args)
    theta_i = (
        DEFAULT_THETA_I_DEG
        if args.theta_i is None
        else angles(args.theta_i, "--theta-i", 0.0, 90.0, upper_open=True)
    )
    out = check_output_dir(args.out, option="--out")
    source = _source(args, args.scene)
    draws = args.draws if args.format == "zemax-bsdf" else (args.draws or 100)
    available = source.count
    if source.from_run and draws > available:
        raise BadInputError(f"{draws} > the run's {available} draws", field="--draws")
    # one writer per folder; an export that died here left files its rerun may replace
    claim = args.claims.enter_context(writing(out, "export", option="--out"))
    unfinished = (claim.previous or {}).get("command") == "export"
    existing = [name for name in planned_files(source, args.format, draws) if (out / name).exists()]
    if existing and not (args.force or unfinished):
        raise BadInputError(
            f"{existing[0]} exists (use --force to overwrite)", file=out / existing[0]
        )
    grid = scatter_grid(np.unique(theta_i), args.azimuth_step, args.radial_step)
    result = run_export(source, args.format, grid, out, args.draws, progress, args.tis_quantile_at)
    if source.from_run:
        record_export(Path(args.run), result)
    for entry in result["files"]:
        for warning in _integral_warnings(entry):
            progress(f"warning: {entry['path']}: {warning}")
    if args.json:
        emit_json(result)
        return 0
    _print_result(result)
    return 0


def _integral_warnings(entry: dict) -> list[str]:
    """Where a table's hemisphere integral misses its TIS line by more than
    :data:`MAX_INTEGRAL_ERROR`, and why: the grid's quadrature error (a finer grid removes it),
    or a pointwise envelope's own excess over the draws' integrals (a finer grid does not; the
    draw at the TIS quantile is the real BRDF)."""
    if "table_integral" not in entry:
        return []
    theta_i = entry["theta_i_deg"]
    miss = np.divide(entry["table_integral"], entry["tis"]) - 1.0
    quadrature = np.asarray(entry["quadrature_error"])
    warnings = []
    k = int(np.argmax(quadrature))
    if quadrature[k] > MAX_INTEGRAL_ERROR:
        warnings.append(
            f"the table's hemisphere integral misses its TIS by {100 * quadrature[k]:.1f} % at "
            f"theta_i = {theta_i[k]:g} deg, the grid's quadrature error; use a finer "
            "--radial-step / --azimuth-step"
        )
    if entry.get("pointwise_envelope"):
        excess = np.asarray(entry["pointwise_excess"])
        k = int(np.argmax(np.abs(excess)))
        if abs(excess[k]) > MAX_INTEGRAL_ERROR:
            warnings.append(
                f"the table's hemisphere integral is {100 * miss[k]:+.1f} % off its TIS line at "
                f"theta_i = {theta_i[k]:g} deg because the table is a pointwise envelope (the "
                f"{_WHAT[entry['kind']]} of each cell over the draws), no BRDF of any posterior "
                f"draw: {100 * excess[k]:+.1f} % against the {_WHAT[entry['kind']]} of the draws' "
                f"own integrals on this grid, whose quadrature error there is "
                f"{100 * quadrature[k]:.2f} %, so a finer grid does not remove it; "
                f"{_TWINS[entry['kind']]}.bsdf is the draw at that TIS quantile, a real BRDF"
            )
    return warnings


def _print_result(result: dict) -> None:
    if result["format"] == "abg":
        rows = [
            [
                f"{r['theta_i_deg']:g}",
                f"{r['A']:.4g}",
                f"{r['B']:.4g}",
                f"{r['g']:.4g}",
                f"{100 * r['tis_model']:.4f}",
                f"{abs(r['tis_abg'] / r['tis_model'] - 1):.1e}",
                f"{r['rms_log_error']:.3f}",
            ]
            for r in result["rows"]
        ]
        headers = ["theta_i [deg]", "A [1/sr]", "B [-]", "g [-]", "TIS [%]", "|TIS_ABg/TIS-1|"]
        print(table([*headers, "rms ln error [-]"], rows))
    else:
        rows = [
            [
                Path(f["path"]).name,
                f["kind"],
                f"{100 * min(f['tis']):.4f}–{100 * max(f['tis']):.4f}",
                f"{np.max(np.abs(np.divide(f['table_integral'], f['tis']) - 1)):.1e}",
            ]
            for f in result["files"]
        ]
        print(table(["file", "kind", "TIS [%]", "max |table integral/TIS-1|"], rows))
    from brdf_infer.model import fold_statement

    folder = Path(result["files"][0]["path"]).parent
    print(fold_statement(result["fold"]))
    print(f"{len(result['files'])} files in {folder}/ ({result['seconds']:.1f} s)")


def _check_file(path: Path, as_json: bool) -> None:
    """Read a .BSDF file; per angle of incidence its TIS line and the table's own integral."""
    from brdf_infer.report.export import read_bsdf, table_integral

    contents = read_bsdf(path)
    if contents.symmetry != "PlaneSymmetrical":
        integrals = np.full(contents.tis.shape, np.nan)
    else:
        integrals = np.array(
            [
                [
                    table_integral(t, contents.azimuth_deg, contents.radial_deg, block)
                    for t, block in zip(contents.theta_i_deg, blocks, strict=True)
                ]
                for blocks in contents.bsdf
            ]
        )
    payload = {
        "path": str(path),
        "symmetry": contents.symmetry,
        "scatter_type": contents.scatter_type,
        "theta_i_deg": contents.theta_i_deg.tolist(),
        "azimuth_deg": contents.azimuth_deg.tolist(),
        "radial_deg": contents.radial_deg.tolist(),
        "tis": contents.tis.tolist(),
        "table_integral": None if np.isnan(integrals).all() else integrals.tolist(),
    }
    if as_json:
        emit_json(payload)
        return
    print(
        f"{path}: {contents.symmetry}, {contents.scatter_type}, "
        f"{contents.theta_i_deg.size} angles of incidence, {contents.azimuth_deg.size} azimuths, "
        f"{contents.radial_deg.size} radials"
    )
    rows = [
        [f"{t:g}", f"{contents.tis[0, k]:.8g}", f"{integrals[0, k]:.6g}"]
        for k, t in enumerate(contents.theta_i_deg)
    ]
    print(table(["theta_i [deg]", "TIS line [-]", "table integral [-]"], rows))
