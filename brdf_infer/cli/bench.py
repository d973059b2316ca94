"""``brdf-infer bench``: error-against-run-time benchmarks. They live in a checkout of the
repository (``benchmarks/`` beside ``brdf_infer/``), not in the installed package: they need
the ``test`` and ``peers`` extras, and write ``reports/`` of the checkout."""

from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path

import brdf_infer
from brdf_infer.cli._common import command_parser, headless, progress
from brdf_infer.errors import BadInputError


def add_parser(commands) -> argparse.ArgumentParser:
    """The options of ``brdf-infer bench``."""
    parser = command_parser(
        commands,
        "bench",
        "error-against-run-time benchmarks of every numerical method (in a checkout of the "
        "repository: its benchmarks/ folder)",
    )
    parser.add_argument("--quick", action="store_true", help="small sizes, a couple of minutes")
    parser.add_argument(
        "--out",
        help="Markdown report path (default: the checkout's reports/benchmarks.md, with --speed "
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


def checkout_benchmarks():
    """The ``benchmarks`` package of the checkout this package is installed from (an editable
    install: ``brdf_infer/``'s parent folder).

    Raises:
        BadInputError: an installed package without its checkout.
    """
    root = Path(brdf_infer.__file__).resolve().parents[1]
    if not (root / "benchmarks" / "__init__.py").is_file():
        raise BadInputError(
            "the benchmarks live in a checkout of the repository (benchmarks/), not in the "
            "installed package: run brdf-infer bench from a checkout set up by ./dev"
        )
    if str(root) not in sys.path:
        sys.path.insert(0, str(root))
    return importlib.import_module("benchmarks"), root


def main(args: argparse.Namespace) -> int:
    """Write the benchmark report asked for (default: ``reports/`` of the checkout)."""
    headless()
    benchmarks, root = checkout_benchmarks()
    reports = root / "reports"
    if args.stress:
        out = Path(args.out or reports / "benchmarks-stress.md")
        path = benchmarks.write_stress_report(out, args.quick, progress=progress)
    elif args.speed:
        out = Path(args.out or reports / "benchmarks-speed.md")
        path = benchmarks.write_speed_report(out, args.quick, progress=progress)
    else:
        out = Path(args.out or reports / "benchmarks.md")
        path = benchmarks.write_report(out, args.quick, progress)
    print(f"benchmark report written to {path}")
    return 0
