"""``brdf-infer bench``: error-against-run-time benchmarks (:mod:`brdf_infer.bench`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from brdf_infer.cli._common import command_parser, headless, progress


def add_parser(commands) -> argparse.ArgumentParser:
    """The options of ``brdf-infer bench``."""
    parser = command_parser(
        commands, "bench", "error-against-run-time benchmarks of every numerical method"
    )
    parser.add_argument("--quick", action="store_true", help="small sizes, a couple of minutes")
    parser.add_argument(
        "--out",
        help="Markdown report path (default: reports/benchmarks.md, with --speed "
        "reports/benchmarks-speed.md)",
    )
    parser.add_argument(
        "--speed",
        action="store_true",
        help="only the main job's speed: run and posterior cold and warm, the gradient, the "
        "peers on the same posterior",
    )
    parser.add_argument(
        "--stress",
        action="store_true",
        help="only the concurrency stress paths, 20 repetitions each under a watchdog "
        "(reports/benchmarks-stress.md)",
    )
    parser.set_defaults(handler=main)
    return parser


def main(args: argparse.Namespace) -> int:
    """Write the benchmark report asked for."""
    headless()
    from brdf_infer.bench import write_report, write_speed_report, write_stress_report

    if args.stress:
        out = Path(args.out or "reports/benchmarks-stress.md")
        path = write_stress_report(out, args.quick, progress=progress)
    elif args.speed:
        out = Path(args.out or "reports/benchmarks-speed.md")
        path = write_speed_report(out, args.quick, progress=progress)
    else:
        path = write_report(Path(args.out or "reports/benchmarks.md"), args.quick, progress)
    print(f"benchmark report written to {path}")
    return 0
