"""``brdf-infer report``: the HTML report of a posterior run (the answer, then diagnostics)."""

from __future__ import annotations

import argparse
from pathlib import Path

from brdf_infer.cli._common import (
    add_json_argument,
    command_parser,
    emit_json,
    headless,
    print_verdict,
    progress,
)


def add_parser(commands) -> argparse.ArgumentParser:
    """The options of ``brdf-infer report``."""
    parser = command_parser(
        commands, "report", "HTML report of a posterior run: the answer, then diagnostics"
    )
    parser.add_argument("run_dir", help="directory of a posterior run (posterior.nc, ...)")
    add_json_argument(parser)
    parser.set_defaults(handler=main)
    return parser


def main(args: argparse.Namespace) -> int:
    """Write the report into the run folder and print its verdict."""
    headless()
    from brdf_infer.report import write_report

    path, verdict = write_report(Path(args.run_dir), progress=progress)
    if args.json:
        emit_json({"report": str(path), "verdict": verdict.as_json()})
        return 0
    print_verdict(verdict.as_json())
    print(f"report: {path}")
    return 0
