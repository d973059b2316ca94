"""``brdf-infer raytrace``: the series II setup (Sec. 6) ray-traced with a parameter set or
over a posterior's draws, compared with the measurements."""

from __future__ import annotations

import argparse
from pathlib import Path

from brdf_infer.cli._common import (
    claimed_output_dir,
    emit_json,
    headless,
    progress,
    scene_command_parser,
    table,
)
from brdf_infer.errors import BadInputError
from brdf_infer.workflow import RUN_TRACE_BAND_RAYS, RUN_TRACE_DRAWS


def add_parser(commands) -> argparse.ArgumentParser:
    """The options of ``brdf-infer raytrace``."""
    parser = scene_command_parser(
        commands,
        "raytrace",
        "ray-trace the series II setup (Sec. 6) and compare with the measurements",
    )
    source = parser.add_mutually_exclusive_group()
    source.add_argument(
        "--params", help="parameter set name or JSON file (default: the scene's reference set)"
    )
    source.add_argument(
        "--run", help="posterior run directory: medians and 95 %% band over its draws"
    )
    parser.add_argument("--rays", type=int, help="rays per configuration (and per draw with --run)")
    parser.add_argument("--seed", type=int, default=0, help="random seed")
    parser.add_argument(
        "--estimator",
        choices=["nee", "naive"],
        default="nee",
        help="next-event estimation or the naive forward ray trace",
    )
    parser.add_argument(
        "--draws", type=int, default=RUN_TRACE_DRAWS, help="--run: draws in the band"
    )
    parser.add_argument(
        "--out",
        help="also write raytrace.json, the detector images (detector_images.npz) and figures here",
    )
    parser.set_defaults(handler=main)
    return parser


def main(args: argparse.Namespace) -> int:
    """Ray-trace, print the comparison and write it to ``--out``."""
    headless()
    from brdf_infer.scene import load_scene

    scene = load_scene(args.scene)
    if scene.raytrace is None:
        raise BadInputError(
            "this scene has no [raytrace] table (the measurement setup of Sec. 6)",
            file=scene.path,
            field="raytrace",
        )
    for option, value, low in (("--rays", args.rays, 1), ("--draws", args.draws, 2)):
        if value is not None and value < low:
            raise BadInputError(f"{option} must be at least {low}, got {value}")
    measurements = scene.load_measurements()
    out = claimed_output_dir(args, args.out, "raytrace") if args.out else None
    payload = _payload(args, scene, measurements)
    for warning in payload["warnings"]:
        progress(f"warning: {warning}")
    if out is not None:
        _write_raytrace(out, scene, measurements, payload)
    if args.json:
        emit_json(payload)
        return 0
    _print_raytrace(payload)
    return 0


def _payload(args: argparse.Namespace, scene, measurements) -> dict:
    from brdf_infer.studies.raytrace import raytrace_payload, raytrace_posterior_payload, thin_draws

    shown = None if args.json else progress
    if args.run is not None:
        from brdf_infer.posterior import draws_params, load_run_family
        from brdf_infer.runs.folder import RunFolder

        member, physical = load_run_family(Path(args.run))
        if not member.paper_parameters:
            raise BadInputError(
                f"a run of {member.name}, not of strumik2024: the ray tracer traces Eq. (7)",
                file=RunFolder(args.run).posterior_file,
            )
        all_draws = draws_params(physical)
        return raytrace_posterior_payload(
            scene,
            measurements,
            thin_draws(all_draws, args.draws),
            f"posterior of {args.run}",
            rays=args.rays or RUN_TRACE_BAND_RAYS,
            seed=args.seed,
            progress=shown,
        )
    from brdf_infer.model.params import resolve_params

    name = args.params or scene.outputs.reference_params or "uv-paper"
    return raytrace_payload(
        scene,
        measurements,
        resolve_params(name),
        name,
        rays=args.rays,
        seed=args.seed,
        estimator=args.estimator,
        progress=shown,
    )


def _write_raytrace(out: Path, scene, measurements, payload: dict) -> None:
    from brdf_infer._internal.atomic import atomic_write_bytes
    from brdf_infer.report import figure_png, plot_detector_images, plot_raytrace
    from brdf_infer.studies.raytrace import write_traces

    out.mkdir(parents=True, exist_ok=True)
    images = write_traces(out, scene, measurements, [payload])
    atomic_write_bytes(out / "raytrace.png", figure_png(plot_raytrace([payload])))
    atomic_write_bytes(out / "detector_images.png", figure_png(plot_detector_images(images)))
    progress(
        f"wrote raytrace.json, detector_images.npz, raytrace.png and detector_images.png in {out}"
    )


def _print_raytrace(payload: dict) -> None:
    print(
        f"series {payload['series']} ray traced with '{payload['params_source']}': "
        f"{payload['rays']} rays per configuration, {payload['estimator']} estimator"
    )
    headers = [
        "theta_i [deg]",
        "delta [deg]",
        "measured",
        "simulated",
        "MC error",
        "point Eq. (6)",
        "sim/meas",
        "image ratio",
    ]
    if payload["draws"]:
        headers.insert(5, "95 % band")
    rows = []
    for row in payload["rows"]:
        cells = [
            f"{row['theta_i_deg']:g}",
            f"{row['delta_deg']:+g}",
            f"{row['measured']:.3e}",
            f"{row['simulated']:.3e}",
            f"{100 * row['mc_se'] / row['simulated']:.2f} %" if row["simulated"] else "-",
            f"{row['point_estimate']:.3e}",
            f"{row['simulated'] / row['measured']:.3f}",
            f"{row['image_ratio']:.3e}",
        ]
        if payload["draws"]:
            cells.insert(5, f"{row['band']['lo95']:.2e}-{row['band']['hi95']:.2e}")
        rows.append(cells)
    print(table(headers, rows))
    print(
        "simulated = dPs/Pi through the detector aperture; image ratio = the paper's Eq. (2) "
        "over the signal rectangle"
    )
    print(f"time: {payload['seconds']:.2f} s (+{payload['compile_seconds']:.2f} s compile)")
