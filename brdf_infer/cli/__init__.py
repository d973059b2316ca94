"""Command line ``brdf-infer`` (also ``python -m brdf_infer``): ``argparse`` and a module per
command, each with ``add_parser(commands)`` and ``main(args) -> int``; the library does the
work.

Each subcommand takes a scene (built-in name or TOML path; default ``lya``). With ``--json``
stdout holds exactly one JSON object; progress goes to stderr. Bad input prints one line on
stderr and exits with code 2.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
from collections.abc import Sequence
from typing import NoReturn

import brdf_infer
from brdf_infer.cli import (
    batch,
    bench,
    brdf,
    compare,
    design,
    export,
    fit,
    posterior,
    predict,
    raytrace,
    report,
    run,
    sbc,
    scenes,
    sensitivity,
    tis,
)
from brdf_infer.cli._common import EXIT_BAD_INPUT, HelpFormatter, Parser, named_by_flag
from brdf_infer.cli._device import placement
from brdf_infer.errors import BadInputError

# in the order ``brdf-infer --help`` lists them
COMMANDS = (
    run,
    fit,
    posterior,
    batch,
    tis,
    brdf,
    raytrace,
    predict,
    sbc,
    export,
    compare,
    sensitivity,
    design,
    report,
    bench,
    scenes,
)
EXIT_INTERRUPTED = 130


def build_parser() -> argparse.ArgumentParser:
    """The ``brdf-infer`` argument parser."""
    parser = Parser(
        prog="brdf-infer",
        description="Bayesian BRDF/TIS inference for black coatings (Strumik et al. 2024).",
        formatter_class=HelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {brdf_infer.__version__}")
    commands = parser.add_subparsers(
        dest="command", required=True, parser_class=Parser, metavar="COMMAND"
    )
    for command in COMMANDS:
        command.add_parser(commands)
    return parser


def _interrupt(signum, frame) -> NoReturn:
    raise KeyboardInterrupt


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code (2 for bad input)."""
    from brdf_infer._internal.precision import Float32Error, require_float64

    args = build_parser().parse_args(argv)
    brdf_infer.use_float64(cache=not args.no_cache)  # before anything is compiled
    signal.signal(signal.SIGTERM, _interrupt)
    if args.no_cache:  # before anything is compiled
        from brdf_infer._internal.cache import disable_compilation_cache

        disable_compilation_cache()
    try:
        if getattr(args, "prepare", None) is not None:  # before JAX starts its backend
            args.prepare(args)
        require_float64()
        # args.claims: the output folders the command holds (one writer per folder)
        with contextlib.ExitStack() as args.claims, placement(args.command, args.device):
            return args.handler(args)
    except BadInputError as error:
        print(f"brdf-infer: error: {named_by_flag(error, args)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except Float32Error as error:
        print(f"brdf-infer: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    # before OSError, its base class: `brdf-infer ... | head`: the reader left, so do we
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    except OSError as error:
        where = f"{error.filename}: " if error.filename else ""
        print(f"brdf-infer: error: {where}{error.strerror or error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        hint = " (continue it with --resume)" if getattr(args, "sampler", None) == "emcee" else ""
        print(f"brdf-infer: interrupted{hint}", file=sys.stderr)
        return EXIT_INTERRUPTED


def entry_point() -> None:
    """Console-script entry point."""
    sys.exit(main())
