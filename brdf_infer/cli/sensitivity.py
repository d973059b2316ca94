"""``brdf-infer sensitivity``: the posterior under the scene's error model and with each
assumption changed (:mod:`brdf_infer.studies.sensitivity`), with the defaults of
:class:`~brdf_infer.scene.settings.SensitivitySettings`."""

from __future__ import annotations

import argparse
import sys

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
from brdf_infer.cli._options import scene_and_measurements
from brdf_infer.scene.settings import SensitivitySettings


def add_parser(commands) -> argparse.ArgumentParser:
    """The options of ``brdf-infer sensitivity``."""
    defaults = SensitivitySettings
    parser = scene_command_parser(
        commands,
        "sensitivity",
        "the posterior under the scene's error model and with each assumption changed "
        "(calibration, rotation coupling, images per row, spread): TIS, π·BRDF0, PSIS-LOO",
    )
    parser.add_argument(
        "--variants",
        nargs="+",
        metavar="KEY=VALUE[,KEY=VALUE]",
        help="error models to compare with the scene's, each [errors] keys changed, e.g. "
        "calibration=none rotation_coupling=camera_fixed images_per_row=1 model=spread "
        "(default: each assumption changed in turn)",
    )
    add_nuts_arguments(parser, defaults, helps={"seed": "random seed (all)"})
    parser.add_argument(
        "--no-refit",
        action="store_true",
        help="no exact refits where Pareto k exceeds its limit (0.7 from 2200 draws)",
    )
    parser.add_argument(
        "--out",
        help="also write sensitivity.json and sensitivity.png here (into a run folder: the "
        "report shows them)",
    )
    parser.set_defaults(handler=main)
    return parser


def main(args: argparse.Namespace) -> int:
    """Run the study (every option and variant checked before sampling) and print it."""
    headless()
    from brdf_infer.report import (
        SENSITIVITY_HEADERS,
        power_scaling_rows,
        sensitivity_rows,
        write_sensitivity,
    )
    from brdf_infer.studies.sensitivity import (
        SENSITIVITY_FIGURE,
        SENSITIVITY_FILE,
        check_scene,
        default_variants,
        parse_variant,
        sensitivity,
    )

    settings = record_from_args(SensitivitySettings, args, refit=not args.no_refit)
    scene, measurements = scene_and_measurements(args.scene)
    check_scene(scene)
    variants = (
        default_variants(scene)
        if args.variants is None
        else [parse_variant(spec, scene) for spec in args.variants]
    )
    out = claimed_output_dir(args, args.out, "sensitivity") if args.out else None
    progress(
        f"sensitivity of scene '{scene.name}' to its error model: the default and "
        f"{len(variants)} variant(s) ({', '.join(v.name for v in variants)}), "
        f"{settings.chains} chains × ({settings.warmup} + {settings.draws}) each ..."
    )
    result = sensitivity(scene, measurements, variants, settings, progress=sys.stderr.isatty())
    payload = result.as_json()
    if out is not None:
        write_sensitivity(out, result)
    if args.json:
        emit_json(payload)
        return 0
    print(f"sensitivity to the error-model assumptions, scene '{scene.name}'")
    print(table(SENSITIVITY_HEADERS, sensitivity_rows(payload)))
    scaling = power_scaling_rows(payload)
    if scaling:
        print("power-scaling sensitivity of the default posterior (> 0.05: it matters)")
        print(table(["quantity", "prior", "likelihood", "diagnosis"], scaling))
    print(f"{result.seconds:.1f} s")
    if out is not None:
        print(f"written: {out / SENSITIVITY_FILE}, {out / SENSITIVITY_FIGURE}")
    return 0
