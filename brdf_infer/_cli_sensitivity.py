"""``brdf-infer sensitivity``: arguments checked before any work, then the library's study."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence

from brdf_infer._outdir import claim_output_dir


def add_sensitivity_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``brdf-infer sensitivity``."""
    from brdf_infer.sensitivity import SensitivitySettings

    defaults = SensitivitySettings()
    parser.add_argument(
        "--variants",
        nargs="+",
        metavar="KEY=VALUE[,KEY=VALUE]",
        help="error models to compare with the scene's, each [errors] keys changed, e.g. "
        "calibration=none rotation_coupling=camera_fixed images_per_row=1 model=spread "
        "(default: each assumption changed in turn)",
    )
    parser.add_argument("--chains", type=int, default=defaults.chains, help="NUTS chains")
    parser.add_argument("--warmup", type=int, default=defaults.warmup, help="NUTS warmup")
    parser.add_argument("--draws", type=int, default=defaults.draws, help="NUTS draws per chain")
    parser.add_argument("--seed", type=int, default=defaults.seed, help="random seed (all)")
    parser.add_argument(
        "--no-refit", action="store_true", help="no exact refits where Pareto k > 0.7"
    )
    parser.add_argument(
        "--out",
        help="also write sensitivity.json and sensitivity.png here (into a run folder: the "
        "report shows them)",
    )


def command_sensitivity(
    args: argparse.Namespace,
    scene_and_measurements: Callable,
    table: Callable[[Sequence[str], Sequence[Sequence[str]]], str],
    progress: Callable[[str], None],
) -> None:
    """Run ``brdf-infer sensitivity`` (every option and variant checked before sampling)."""
    from brdf_infer.report import (
        SENSITIVITY_HEADERS,
        power_scaling_rows,
        sensitivity_rows,
        write_sensitivity,
    )
    from brdf_infer.sensitivity import (
        SENSITIVITY_FIGURE,
        SENSITIVITY_FILE,
        SensitivitySettings,
        check_scene,
        default_variants,
        parse_variant,
        sensitivity,
    )

    settings = SensitivitySettings(
        chains=args.chains,
        warmup=args.warmup,
        draws=args.draws,
        seed=args.seed,
        refit=not args.no_refit,
    )
    settings.check()
    scene, measurements = scene_and_measurements(args.scene)
    check_scene(scene)
    variants = (
        default_variants(scene)
        if args.variants is None
        else [parse_variant(spec, scene) for spec in args.variants]
    )
    out = claim_output_dir(args.out, "sensitivity", args.claims) if args.out else None
    progress(
        f"sensitivity of scene '{scene.name}' to its error model: the default and "
        f"{len(variants)} variant(s) ({', '.join(v.name for v in variants)}), "
        f"{settings.chains} chains × ({settings.warmup} + {settings.draws}) each ..."
    )
    result = sensitivity(
        scene,
        measurements,
        variants,
        settings,
        progress=sys.stderr.isatty(),
    )
    payload = result.as_json()
    if out is not None:
        write_sensitivity(out, result)
    if args.json:
        print(json.dumps(payload))
        return
    print(f"sensitivity to the error-model assumptions, scene '{scene.name}'")
    print(table(SENSITIVITY_HEADERS, sensitivity_rows(payload)))
    scaling = power_scaling_rows(payload)
    if scaling:
        print("power-scaling sensitivity of the default posterior (> 0.05: it matters)")
        print(table(["quantity", "prior", "likelihood", "diagnosis"], scaling))
    print(f"{result.seconds:.1f} s")
    if out is not None:
        print(f"written: {out / SENSITIVITY_FILE}, {out / SENSITIVITY_FIGURE}")
