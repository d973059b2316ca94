"""``brdf-infer batch``: posteriors of many scenes (:mod:`brdf_infer.batch`) with the defaults
of :class:`~brdf_infer.settings.BatchSettings`."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from brdf_infer.cli._common import (
    add_json_argument,
    claimed_output_dir,
    command_parser,
    emit_json,
    headless,
    progress,
    record_from_args,
    table,
)
from brdf_infer.cli._options import add_force_argument, add_model_argument
from brdf_infer.settings import BATCH_MODES, BatchSettings, check_family_name


def add_parser(commands) -> argparse.ArgumentParser:
    """The options of ``brdf-infer batch``."""
    defaults = BatchSettings
    parser = command_parser(
        commands, "batch", "posteriors of many scenes, one compiled program per model structure"
    )
    parser.add_argument("scenes", nargs="+", metavar="SCENE_OR_GLOB", help="scenes or globs")
    parser.add_argument(
        "--sampler", choices=["nuts"], default="nuts", help="sampler (NUTS: one compiled program)"
    )
    parser.add_argument("--chains", type=int, default=defaults.chains, help="NUTS chains per scene")
    parser.add_argument("--draws", type=int, default=defaults.draws, help="NUTS draws per chain")
    parser.add_argument("--warmup", type=int, default=defaults.warmup, help="NUTS warmup per chain")
    parser.add_argument(
        "--seed", type=int, default=defaults.seed, help="random seed (as posterior --seed)"
    )
    parser.add_argument(
        "--target-accept",
        type=float,
        default=defaults.target_accept,
        help="NUTS target acceptance",
    )
    parser.add_argument(
        "--mode",
        choices=list(BATCH_MODES),
        default=defaults.mode,
        help="threads: one scene per CPU thread; vmap: one vmapped program, the scene axis "
        "sharded over every device (auto: threads on a single CPU, else vmap)",
    )
    parser.add_argument("--out", help="output directory (default: reports/batch)")
    parser.add_argument(
        "--resume",
        action="store_true",
        help="keep the scenes whose run folders in --out are complete (same scene, data and "
        "settings) and run the rest",
    )
    add_json_argument(parser)
    add_model_argument(parser)
    add_force_argument(parser)
    parser.set_defaults(handler=main)
    return parser


def main(args: argparse.Namespace) -> int:
    """Run the batch (SIGINT and SIGTERM keep the complete run folders) and print a table."""
    headless()
    from brdf_infer.batch import BatchInterrupted, run_batch_until_signalled

    check_family_name(args.model)
    settings = record_from_args(BatchSettings, args)
    out = claimed_output_dir(args, args.out or Path("reports") / "batch", "batch")
    try:
        result = run_batch_until_signalled(
            args.scenes, out, settings, model=args.model, progress=progress, resume=args.resume
        )
    except BatchInterrupted as interrupted:
        # the complete run folders and batch.json are on disk, nothing half-written is left;
        # end now: the batch's threads may still run (they cannot be joined), and the
        # interpreter's teardown with JAX loaded alone takes seconds
        print(f"brdf-infer: {interrupted.message(out)}", file=sys.stderr, flush=True)
        sys.stdout.flush()
        os._exit(interrupted.exit_code)
    if args.json:
        emit_json({"out": str(out), **result.as_json()})
        return 0
    _print_result(result, out)
    return 0


def _print_result(result, out: Path) -> None:
    rows = []
    for entry in result.entries:
        item = entry.as_json()
        if entry.error is not None:
            rows.append([item["scene"], "skipped", "", "", "", "", entry.error])
            continue
        at = item["tis"]["theta_i_deg"].index(70.0) if item["tis"] else None
        tis70 = (
            "–"
            if at is None
            else f"{100 * item['tis']['median'][at]:.2f} "
            f"({100 * item['tis']['lo95'][at]:.2f}–{100 * item['tis']['hi95'][at]:.2f})"
        )
        rows.append(
            [
                item["scene"],
                item["model"],
                f"{item['r_hat_max']:.3f}",
                f"{item['ess_min']:.0f}",
                str(item["divergences"]),
                "pass" if item["verdict"]["ok"] else f"{len(item['verdict']['lines'])} failed",
                f"TIS(70°) {tis70} %; {item['out']}",
            ]
        )
    headers = ["scene", "model", "R-hat max", "ESS min", "divergences", "verdict", "result"]
    print(table(headers, rows))
    print(
        f"{len(result.entries)} scene(s) in {result.groups} compiled group(s) on "
        f"{result.devices} device(s): {result.seconds:.1f} s ({result.compile_seconds:.1f} s "
        f"compiling); summary in {out / 'batch.json'}"
    )
