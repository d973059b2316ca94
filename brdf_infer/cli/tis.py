"""``brdf-infer tis``: the total integrated scatter, Eq. (9), of a parameter set (with its
quadrature error) or a posterior run (a credible band over its draws)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from brdf_infer.cli._common import add_json_argument, command_parser, emit_json, progress, table
from brdf_infer.cli._options import (
    add_fold_arguments,
    add_run_target_arguments,
    angles,
    checked_run_target,
    chosen_fold,
    folded_family,
)


def add_parser(commands) -> argparse.ArgumentParser:
    """The options of ``brdf-infer tis``."""
    parser = command_parser(
        commands, "tis", "total integrated scatter, Eq. (9), of a parameter set or a run"
    )
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--params", help="parameter set name or JSON file (default: uv-paper)")
    source.add_argument("--run", help="posterior run directory: credible band over its draws")
    parser.add_argument(
        "--theta-i", type=float, nargs="+", default=[0, 5, 30, 50, 70], help="θi [deg]"
    )
    add_fold_arguments(parser, "a parameter set: no folding; a run: its scene's [outputs] fold")
    add_run_target_arguments(parser)
    add_json_argument(parser)
    parser.set_defaults(handler=main)
    return parser


def main(args: argparse.Namespace) -> int:
    """Print the TIS of ``--params`` (default uv-paper) or the band of ``--run``."""
    from brdf_infer.model import fold_statement, tis_with_error
    from brdf_infer.model.params import resolve_params

    theta_i = angles(args.theta_i, "--theta-i", 0.0, 90.0, upper_open=True)
    checked_run_target(args)
    if args.run is not None:
        _tis_from_run(args, theta_i)
        return 0
    name = args.params or "uv-paper"
    params = resolve_params(name)
    fold = chosen_fold(args.fold)
    (values, errors), first, second = _timed(tis_with_error, theta_i, params, fold=fold)
    values, errors = np.asarray(values), np.asarray(errors)
    warnings = _tis_warnings(theta_i, values)
    for warning in warnings:
        progress(f"warning: {warning}")
    if args.json:
        emit_json(
            {
                "theta_i_deg": theta_i.tolist(),
                "tis": values.tolist(),
                "abs_error": errors.tolist(),
                "fold": fold,
                "warnings": warnings,
                "seconds": second,
                "compile_seconds": first - second,
            }
        )
        return 0
    print(f"TIS, Eq. (9), parameters '{name}'; {fold_statement(fold)}")
    rows = [
        [f"{t:g}", f"{100 * v:.4f}", f"{e:.1e}"]
        for t, v, e in zip(theta_i, values, errors, strict=True)
    ]
    print(table(["theta_i [deg]", "TIS [%]", "quadrature error [-]"], rows))
    print(
        f"time: {1e3 * second:.2f} ms for {theta_i.size} angles (+{first - second:.2f} s compile)"
    )
    return 0


def _timed(function, *args, **kwargs):
    """(result, seconds of the first call incl. compilation, seconds of a second call)."""
    import jax

    start = time.perf_counter()
    result = jax.block_until_ready(function(*args, **kwargs))
    first = time.perf_counter() - start
    start = time.perf_counter()
    jax.block_until_ready(function(*args, **kwargs))
    return result, first, time.perf_counter() - start


def _tis_warnings(theta_i: np.ndarray, values: np.ndarray) -> list[str]:
    """TIS above 1 means more power scattered than incident: the parameters are unphysical."""
    unphysical = theta_i[np.asarray(values) > 1.0]
    if unphysical.size == 0:
        return []
    listed = ", ".join(f"{t:g}" for t in unphysical)
    return [f"TIS > 1 at theta_i = {listed} deg: these parameters are not physical"]


def _tis_from_run(args: argparse.Namespace, theta_i: np.ndarray) -> None:
    from brdf_infer.model import fold_statement
    from brdf_infer.posterior import FAMILY_TIS_DRAWS, QUESTIONS, load_run_target, tis_band

    start = time.perf_counter()
    member, physical, target = load_run_target(Path(args.run), args.target, args.sample)
    member = folded_family(member, args.fold)
    fold = member.fold
    # the run's own draws: a lobe family's band over the same evenly spaced draws as the run's
    # (its TIS is a 2-D quadrature, ≈ 1 ms each), so the two intervals are one
    band = tis_band(member, physical, theta_i, FAMILY_TIS_DRAWS)
    band.setdefault("draws", int(np.size(next(iter(physical.values())))))  # every draw
    what = "Eq. (9)" if member.paper_parameters else member.name
    seconds = time.perf_counter() - start
    if args.json:
        emit_json(
            {
                **band,
                "model": member.name,
                "fold": fold,
                "target": target,
                "sample": args.sample,
                "seconds": seconds,
            }
        )
        return
    print(f"TIS, {what}, over {band['draws']} posterior draws of {args.run}")
    which = f"sample {args.sample}" if args.sample else target
    print(f"target: {which}, {QUESTIONS[target]}")
    print(fold_statement(fold))
    rows = [
        [f"{t:g}", *(f"{100 * band[k][i]:.3f}" for k in ("median", "lo68", "hi68", "lo95", "hi95"))]
        for i, t in enumerate(theta_i)
    ]
    headers = ["theta_i [deg]", "median [%]", "16 % [%]", "84 % [%]", "2.5 % [%]", "97.5 % [%]"]
    print(table(headers, rows))
    print(f"time: {seconds:.2f} s")
