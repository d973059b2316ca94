"""``brdf-infer sbc``: simulation-based calibration of a scene's posterior
(:func:`brdf_infer.studies.sbc.run_sbc`) with the defaults of
:class:`~brdf_infer.scene.settings.SbcSettings`."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from brdf_infer.cli._common import (
    add_nuts_arguments,
    claimed_output_dir,
    emit_json,
    headless,
    progress,
    record_from_args,
    scene_command_parser,
    table,
)
from brdf_infer.cli._options import (
    add_instrument_argument,
    add_model_argument,
    scene_and_measurements,
)
from brdf_infer.scene.settings import SbcSettings, check_family_name


def add_parser(commands) -> argparse.ArgumentParser:
    """The options of ``brdf-infer sbc``."""
    defaults = SbcSettings
    parser = scene_command_parser(
        commands, "sbc", "simulation-based calibration: is the scene's posterior calibrated?"
    )
    parser.add_argument(
        "--replicates", type=int, default=defaults.replicates, help="simulated data sets"
    )
    parser.add_argument(
        "--thin", type=int, default=defaults.thin, help="keep every THIN-th NUTS draw"
    )
    add_nuts_arguments(
        parser, defaults, per="replicate", helps={"draws": "posterior draws per replicate"}
    )
    parser.add_argument(
        "--sigma-scale",
        type=float,
        default=defaults.sigma_scale,
        help="planted fault: scale the likelihood sigma by this in the inference only",
    )
    parser.add_argument(
        "--planted-fault",
        default=defaults.planted_fault,
        help="planted fault in the inference only, which SBC must flag: jacobian (the "
        "whitening's log-Jacobian dropped) or prior (every free prior moved by one sd)",
    )
    parser.add_argument(
        "--warmup-tree-depth",
        type=int,
        default=defaults.warmup_tree_depth,
        help="largest NUTS tree depth during the warmup (10 after it)",
    )
    parser.add_argument("--out", help="output directory (default: reports/<scene>/sbc)")
    add_model_argument(parser)
    add_instrument_argument(parser)
    parser.set_defaults(handler=main)
    return parser


def main(args: argparse.Namespace) -> int:
    """Run SBC (every setting checked before any work), write it and print its verdict."""
    headless()
    from brdf_infer.report import write_sbc
    from brdf_infer.studies.sbc import COVERAGE_LEVELS, check_planted_fault, run_sbc

    check_family_name(args.model)
    settings = record_from_args(SbcSettings, args)
    scene, measurements = scene_and_measurements(args.scene, args.instrument)
    check_planted_fault(args.planted_fault, scene, args.model)
    out = claimed_output_dir(args, args.out or Path("reports") / scene.name / "sbc", "sbc")
    progress(
        f"simulation-based calibration of scene '{scene.name}': {settings.replicates} "
        f"replicates, truth ranked among {settings.draws} draws ..."
    )
    result = run_sbc(
        scene,
        measurements,
        settings,
        model=args.model,
        progress=not args.json and sys.stderr.isatty(),
    )
    write_sbc(out, result)
    if args.json:
        emit_json({"out": str(out), **result.as_json()})
        return 0
    rows = [
        [
            name,
            f"{result.chi2_p[name]:.3f}",
            f"{result.ks_p[name]:.3f}",
            *(f"{100 * result.coverage[level][name]:.1f}" for level in COVERAGE_LEVELS),
        ]
        for name in result.quantities
    ]
    print(f"SBC of scene '{scene.name}': {settings.replicates} replicates, {settings.draws} draws")
    print(table(["quantity", "chi2 p", "KS p", "50 % cov", "90 % cov", "95 % cov"], rows))
    verdict = "calibrated" if result.passed else "NOT calibrated: " + "; ".join(result.failures)
    print(f"verdict: {verdict}")
    print(
        f"time: {result.seconds:.0f} s ({result.compile_seconds:.0f} s compiling); "
        f"results in {out}/ (sbc.json, sbc.html)"
    )
    return 0
