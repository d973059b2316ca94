"""``brdf-infer batch``: posteriors of many scenes (:mod:`brdf_infer.workflow.batch`) with the
defaults of :class:`~brdf_infer.scene.settings.BatchSettings`."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from brdf_infer._internal.shards import resolve_shard
from brdf_infer.cli._common import (
    add_json_argument,
    add_nuts_arguments,
    command_parser,
    emit_json,
    headless,
    progress,
    record_from_args,
    table,
)
from brdf_infer.cli._options import add_force_argument, add_model_argument
from brdf_infer.cli._outdir import check_output_dir
from brdf_infer.scene.settings import BATCH_MODES, BatchSettings, check_family_name


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
    add_nuts_arguments(
        parser,
        defaults,
        helps={"chains": "NUTS chains per scene", "seed": "random seed (as posterior --seed)"},
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
    _add_shard_argument(parser)
    add_json_argument(parser)
    add_model_argument(parser)
    add_force_argument(parser)
    parser.set_defaults(handler=main)
    return parser


def _add_shard_argument(parser: argparse.ArgumentParser) -> None:
    """``--shard K/N``."""
    parser.add_argument(
        "--shard",
        metavar="K/N",
        help="run scenes K, K+N, K+2N, ... of the list (0 <= K < N; 'slurm': K and N from "
        "SLURM_PROCID and SLURM_NTASKS): the same command in N processes, on any hosts "
        "sharing --out; the last shard to finish writes batch.json",
    )


def main(args: argparse.Namespace) -> int:
    """Run the batch (SIGINT and SIGTERM keep the complete run folders) and print a table."""
    shard = resolve_shard(args.shard)  # a bad --shard creates nothing
    headless()
    from brdf_infer.workflow.batch import (
        BatchInterrupted,
        hold_output,
        run_batch_until_signalled,
    )

    check_family_name(args.model)
    settings = record_from_args(BatchSettings, args)
    out = check_output_dir(args.out or Path("reports") / "batch", option="--out")
    args.claims.enter_context(hold_output(out, shard, option="--out"))  # refused before work
    try:
        result = run_batch_until_signalled(
            args.scenes,
            out,
            settings,
            model=args.model,
            progress=progress,
            resume=args.resume,
            shard=shard,
        )
    except BatchInterrupted as interrupted:
        # the complete run folders (and batch.json) are on disk, nothing half-written is
        # left; end now: the batch's threads may still run (they cannot be joined), and the
        # interpreter's teardown with JAX loaded alone takes seconds
        print(f"brdf-infer: {interrupted.message(out)}", file=sys.stderr, flush=True)
        sys.stdout.flush()
        os._exit(interrupted.exit_code)
    return _report(args, result, out)


def _report(args: argparse.Namespace, result, out: Path) -> int:
    if args.json:
        emit_json({"out": str(out), **result.as_json(), "merged": result.merged})
        return 0
    _print_result(result, out)
    return 0


def _print_result(result, out: Path) -> None:
    rows = []
    for item in result.as_json()["scenes"]:
        if item["out"] is None:
            rows.append([item["scene"], "skipped", "", "", "", "", item["error"]])
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
    summary = (
        f"summary in {out / 'batch.json'}"
        if result.merged
        else "batch.json: written by the last shard to finish"
    )
    print(
        f"{len(result.entries)} scene(s) in {result.groups} compiled group(s) on "
        f"{result.devices} device(s): {result.seconds:.1f} s ({result.compile_seconds:.1f} s "
        f"compiling); {summary}"
    )
