"""``brdf-infer posterior``: :func:`brdf_infer.posterior.run_posterior` (NUTS, Laplace + PSIS
or emcee) with the defaults of :class:`~brdf_infer.scene.settings.PosteriorSettings`."""

from __future__ import annotations

import argparse
from pathlib import Path

from brdf_infer.cli._common import (
    add_nuts_arguments,
    add_strict_model_argument,
    claimed_output_dir,
    emit_json,
    model_exit_code,
    print_posterior_summary,
    print_verdict,
    progress,
    record_from_args,
    scene_command_parser,
)
from brdf_infer.cli._options import (
    add_force_argument,
    add_instrument_argument,
    add_model_argument,
    add_product_switches,
    forced,
    scene_and_measurements,
    with_product_switches,
)
from brdf_infer.scene.settings import (
    EMCEE_BURN_IN,
    LAPLACE_MIN_ROWS,
    NUTS_WARMUP,
    SAMPLERS,
    PosteriorSettings,
    check_family_name,
    resolved_sampler,
)


def add_parser(commands) -> argparse.ArgumentParser:
    """The options of ``brdf-infer posterior``."""
    defaults = PosteriorSettings
    parser = scene_command_parser(
        commands,
        "posterior",
        "sample the posterior (NUTS, Laplace + PSIS for large tables, or emcee)",
    )
    parser.add_argument(
        "--sampler",
        choices=list(SAMPLERS),
        default=defaults.sampler,
        help=f"sampler (auto: laplace from {LAPLACE_MIN_ROWS} rows, nuts below)",
    )
    add_nuts_arguments(
        parser,
        defaults,
        helps={
            "draws": "draws per chain (NUTS; Laplace: its chains x draws proposals are resampled "
            "into as many draws)",
            "warmup": f"NUTS warmup per chain ({NUTS_WARMUP}) or emcee burn-in steps "
            f"({EMCEE_BURN_IN})",
            "target_accept": "NUTS target acceptance probability (raise towards 0.95 if a run "
            "diverges)",
        },
    )
    parser.add_argument(
        "--walkers",
        type=int,
        default=defaults.walkers,
        help="emcee walkers (default: max(24, 2 x dimension))",
    )
    parser.add_argument("--steps", type=int, default=defaults.steps, help="emcee steps")
    parser.add_argument("--out", help="output directory (default: reports/<scene>/<sampler>)")
    parser.add_argument("--resume", action="store_true", help="continue an interrupted emcee run")
    parser.add_argument(
        "--error-model",
        choices=["generative", "spread"],
        help="override the scene's errors.model (spread: the earlier model, for comparison)",
    )
    add_model_argument(parser)
    add_instrument_argument(parser)
    add_force_argument(parser)
    add_product_switches(parser)
    add_strict_model_argument(parser)
    parser.set_defaults(handler=main)
    return parser


def main(args: argparse.Namespace) -> int:
    """Sample the posterior into ``--out`` and print its summary and verdict."""
    from brdf_infer.posterior import run_posterior

    check_family_name(args.model)
    settings = record_from_args(PosteriorSettings, args)  # every setting checked first
    scene, measurements = scene_and_measurements(args.scene, args.instrument, args.force)
    scene = with_product_switches(scene, args)
    passed = forced(scene, measurements)
    out = claimed_output_dir(
        args,
        args.out
        or Path("reports") / scene.name / resolved_sampler(args.sampler, len(measurements)),
        "posterior",
    )
    run = run_posterior(
        scene,
        measurements,
        settings,
        out=out,
        resume=args.resume,
        error_model=args.error_model,
        model=args.model,
        announce=lambda what: progress(what + " ..."),
        forced=passed,
    )
    summary = run.summary
    if args.json:
        emit_json({"out": str(out), **summary})
    else:
        print_posterior_summary(summary, out)
        print_verdict(summary["verdict"])
    return model_exit_code(args, summary)
