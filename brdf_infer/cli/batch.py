"""``brdf-infer batch``: posteriors of many scenes (:mod:`brdf_infer.workflow.batch`) with the
defaults of :class:`~brdf_infer.scene.settings.BatchSettings`."""

from __future__ import annotations

import argparse
import os
import signal
import sys
from pathlib import Path
from typing import NoReturn

from brdf_infer._internal.processes import PEER_TIMEOUT, resolve_processes
from brdf_infer.cli._common import (
    add_json_argument,
    add_nuts_arguments,
    claimed_output_dir,
    command_parser,
    emit_json,
    headless,
    named_by_flag,
    progress,
    record_from_args,
    table,
)
from brdf_infer.cli._options import add_force_argument, add_model_argument
from brdf_infer.cli._outdir import check_output_dir
from brdf_infer.errors import BadInputError
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
    _add_process_arguments(parser)
    add_json_argument(parser)
    add_model_argument(parser)
    add_force_argument(parser)
    parser.set_defaults(handler=main, prepare=prepare)
    return parser


def _add_process_arguments(parser: argparse.ArgumentParser) -> None:
    """``--num-processes``, ``--process-id``, ``--coordinator``, ``--peer-timeout``."""
    parser.add_argument(
        "--num-processes",
        type=int,
        default=1,
        help="run the batch over this many processes (jax.distributed; the same command in "
        "each): scene k of the list goes to process k mod N, process 0 writes batch.json",
    )
    parser.add_argument(
        "--process-id",
        type=int,
        help="this process's id, 0 to N-1 (default: SLURM_PROCID, as srun sets it)",
    )
    parser.add_argument(
        "--coordinator",
        metavar="HOST:PORT",
        help="where process 0 listens (default: JAX_COORDINATOR_ADDRESS, else the first host "
        "of the SLURM job step)",
    )
    parser.add_argument(
        "--peer-timeout",
        type=float,
        default=PEER_TIMEOUT,
        help="seconds without a heartbeat after which a process is taken as failed",
    )


def prepare(args: argparse.Namespace) -> None:
    """Check the process options and, for several processes, connect this one to the others
    (before JAX computes anything); bad options or --out create nothing."""
    args.processes = resolve_processes(
        args.coordinator, args.num_processes, args.process_id, args.peer_timeout
    )
    if args.processes.several:
        from brdf_infer.workflow.batch import join_processes

        check_output_dir(args.out or Path("reports") / "batch")
        join_processes(args.processes)


def main(args: argparse.Namespace) -> int:
    """Run the batch (SIGINT and SIGTERM keep the complete run folders) and print a table."""
    headless()
    from brdf_infer.workflow.batch import BatchInterrupted, run_batch_until_signalled

    check_family_name(args.model)
    settings = record_from_args(BatchSettings, args)
    if not hasattr(args, "processes"):  # called without brdf_infer.cli.main
        prepare(args)
    if args.processes.several:
        return _main_together(args, settings)
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
    return _report(args, result, out)


def _main_together(args: argparse.Namespace, settings: BatchSettings) -> int:
    """This process's share of a batch over several processes
    (:class:`brdf_infer.workflow.batch.Team`): process 0 holds --out and writes batch.json; a
    process that fails tells the others, and each ends with one line on stderr."""
    from brdf_infer.workflow.batch import (
        BatchInterrupted,
        PeerFailed,
        Team,
        remove_stale_partials,
        run_batch_until_signalled,
    )

    processes = args.processes
    out, problem = Path(args.out or Path("reports") / "batch"), None
    if processes.index == 0:
        try:
            out = claimed_output_dir(args, out, "batch")
            remove_stale_partials(out)  # before the others start
        except BadInputError as error:
            problem = error
    try:
        team = Team.start(processes, out, None if problem is None else str(problem))
    except PeerFailed as failure:
        _end(f"brdf-infer: error: {failure} (process {processes.index} stopped)", 1)
    if team is None:
        raise problem
    try:
        result = run_batch_until_signalled(
            args.scenes,
            out,
            settings,
            model=args.model,
            progress=progress,
            resume=args.resume,
            team=team,
        )
    except PeerFailed as failure:
        team.leave()
        where = f"; {out / 'batch.json'} lists the complete scenes" if processes.index == 0 else ""
        _end(f"brdf-infer: error: {failure} (process {processes.index} stopped{where})", 1)
    except BatchInterrupted as interrupted:
        team.fail(f"interrupted ({signal.Signals(interrupted.signum or 2).name})")
        team.leave()
        _end(f"brdf-infer: {interrupted.message(out)}", interrupted.exit_code)
    except BaseException as error:
        team.fail(f"{named_by_flag(error, args) if isinstance(error, BadInputError) else error}")
        team.leave()
        raise
    team.leave()
    if processes.index != 0:  # stdout is process 0's: one table, one JSON object
        mine = sum(processes.owns(k) and e.done for k, e in enumerate(result.entries))
        print(
            f"process {processes.index} of {processes.count}: {mine} scene(s) written; "
            f"{out / 'batch.json'} written by process 0",
            file=sys.stderr,
        )
        return 0
    return _report(args, result, out)


def _end(line: str, code: int) -> NoReturn:
    """Print ``line`` on stderr and end the process at once (the batch's threads may still
    run: they cannot be joined)."""
    print(line, file=sys.stderr, flush=True)
    sys.stdout.flush()
    os._exit(code)


def _report(args: argparse.Namespace, result, out: Path) -> int:
    if args.json:
        emit_json({"out": str(out), **result.as_json()})
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
    print(
        f"{len(result.entries)} scene(s) in {result.groups} compiled group(s) on "
        f"{result.devices} device(s): {result.seconds:.1f} s ({result.compile_seconds:.1f} s "
        f"compiling); summary in {out / 'batch.json'}"
    )
