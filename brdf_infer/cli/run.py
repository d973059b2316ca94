"""``brdf-infer run``: the main job, :func:`brdf_infer.workflow.run`, with the defaults of
:class:`~brdf_infer.scene.settings.RunSettings`."""

from __future__ import annotations

import argparse
from pathlib import Path

from brdf_infer.cli._common import (
    add_nuts_arguments,
    add_strict_model_argument,
    claimed_output_dir,
    emit_json,
    headless,
    model_exit_code,
    print_posterior_summary,
    print_verdict,
    progress,
    record_from_args,
    scene_command_parser,
)
from brdf_infer.cli._options import (
    ERROR_MODEL_REGISTRY,
    FAMILY_REGISTRY,
    INSTRUMENT_REGISTRY,
    add_force_argument,
    add_instrument_argument,
    add_model_argument,
    add_product_switches,
    scene_and_measurements,
    with_known_names,
    with_product_switches,
)
from brdf_infer.errors import BadInputError
from brdf_infer.scene.settings import AUTO_MODEL, RunSettings, check_family_name


def add_parser(commands) -> argparse.ArgumentParser:
    """The options of ``brdf-infer run``."""
    parser = scene_command_parser(
        commands,
        "run",
        "main job: paper fit, least squares, NUTS posterior and report in reports/<scene>/, "
        "plus the studies the scene's [studies] table or the options below ask for",
    )
    parser.add_argument("--out", help="output directory (default: reports/<scene>)")
    parser.add_argument("--example", help="also write the small committed example report here")
    add_nuts_arguments(parser, RunSettings)
    studies = parser.add_argument_group(
        "studies (default: the scene's [studies] table; any of these replaces it)"
    )
    studies.add_argument(
        "--full",
        action="store_true",
        help="every study the scene can run (other error model, instrument models, ray "
        "traces, model comparison, sensitivity to the error-model assumptions, where to "
        "measure next)",
    )
    for option, metavar, registry, what in (
        ("--error-models", "NAME", ERROR_MODEL_REGISTRY, "posteriors under these error models"),
        ("--instruments", "NAME", INSTRUMENT_REGISTRY, "posteriors under these instrument models"),
    ):
        action = studies.add_argument(option, nargs="+", metavar=metavar, help=f"{what}: %(known)s")
        with_known_names(action, registry)
    studies.add_argument("--raytrace", action="store_true", help="ray-trace the posterior")
    action = studies.add_argument(
        "--compare",
        nargs="+",
        metavar="FAMILY",
        help="model families compared by PSIS-LOO, two or more of %(known)s",
    )
    with_known_names(action, FAMILY_REGISTRY)
    studies.add_argument(
        "--sensitivity",
        action="store_true",
        help="posteriors with each error-model assumption changed (brdf-infer sensitivity)",
    )
    studies.add_argument(
        "--design",
        metavar="TARGET",
        help="where to measure next for TARGET (brdf-infer design: tis:70, pi_brdf0, a "
        "parameter, brdf:THETA_I,THETA_S or all), with the scene's [design] budget",
    )
    add_model_argument(parser, auto=True)
    add_instrument_argument(parser)
    add_force_argument(parser)
    add_product_switches(parser)
    add_strict_model_argument(parser)
    parser.set_defaults(handler=main)
    return parser


def main(args: argparse.Namespace) -> int:
    """Run the main job (options checked before any work) and print its summary."""
    headless()
    from brdf_infer.workflow import run

    if args.model != AUTO_MODEL:
        check_family_name(args.model)
    # the input checks stop here, the fits' in run(); run() reports what it is forced past
    scene, measurements = scene_and_measurements(args.scene, args.instrument, args.force)
    scene = with_product_switches(scene, args)
    settings = record_from_args(RunSettings, args, studies=requested_studies(args, scene))
    out = claimed_output_dir(args, args.out or Path("reports") / scene.name, "run")
    result = run(
        scene,
        measurements,
        out,
        settings,
        example=Path(args.example) if args.example else None,
        progress=progress,
    )
    if args.json:
        emit_json(result.as_json())
    else:
        _print_result(result, scene, measurements, out)
    return model_exit_code(args, result.posterior)


def _print_result(result, scene, measurements, out: Path) -> None:
    paper, lsq = result.paper_fit, result.lsq
    print(f"scene '{scene.name}': {len(measurements)} measurements, model {result.model}")
    if paper is not None:
        print(
            f"paper fit: sigma_E = {100 * paper['sigma_e']:.2f} % on {paper['n_points']} points "
            f"(selection '{paper['selection']}')"
        )
    print(
        f"least squares: chi2 = {lsq['cost']:.2f} for {lsq['n_points']} points "
        f"({lsq['starts_converged']}/{lsq['starts']} starts at the optimum); "
        f"fit quality {lsq['fit_quality']}"
    )
    print_posterior_summary(result.posterior, out)
    if result.comparison is not None:
        best = result.comparison["models"][0]
        untrusted = [m["name"] for m in result.comparison["models"] if not m["sampler_ok"]]
        caveat = (
            f"; sampler diagnostics fail for {', '.join(untrusted)}: not to be trusted in the "
            "ranking"
            if untrusted
            else ""
        )
        print(f"model comparison: {best['name']} first (PSIS-LOO, see the report){caveat}")
    print_verdict(result.verdict.as_json())
    print(f"report: {result.report}")
    # the whole job (fits, posterior, studies, report), not the posterior's line above
    print(f"done in {result.seconds:.1f} s (the whole job)")


def requested_studies(args: argparse.Namespace, scene):
    """The studies the options ask for (None: none given, the scene's ``[studies]``)."""
    from brdf_infer.instrument import INSTRUMENT_MODELS
    from brdf_infer.model import FAMILY_NAMES
    from brdf_infer.model.error_model import ERROR_MODELS
    from brdf_infer.scene import Studies
    from brdf_infer.scene.design_target import parse_target
    from brdf_infer.workflow import full_studies

    if args.full:
        return full_studies(scene)
    given = (args.error_models, args.instruments, args.compare)
    if all(value is None for value in given) and not (
        args.raytrace or args.sensitivity or args.design
    ):
        return None
    if args.design is not None:
        parse_target(args.design, field="--design")
    for option, values, known in (
        ("--error-models", args.error_models, ERROR_MODELS),
        ("--instruments", args.instruments, INSTRUMENT_MODELS),
        ("--compare", args.compare, FAMILY_NAMES),
    ):
        for value in values or ():
            if value not in known:
                raise BadInputError(
                    f"unknown name {value!r} (known: {', '.join(known)})", field=option
                )
    if args.compare is not None and len(set(args.compare)) < 2:
        raise BadInputError("name at least two families to compare", field="--compare")
    if args.raytrace and scene.raytrace is None:
        raise BadInputError(
            "the scene has no [raytrace] table to ray-trace with",
            file=scene.path,
            field="--raytrace",
        )
    return Studies(
        error_models=tuple(args.error_models or ()),
        instruments=tuple(args.instruments or ()),
        raytrace=args.raytrace,
        compare=tuple(dict.fromkeys(args.compare or ())),
        sensitivity=args.sensitivity,
        design=args.design,
    )
