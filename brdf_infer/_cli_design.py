"""``brdf-infer design``: arguments checked before any work, then the library's study."""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable, Sequence
from pathlib import Path

from brdf_infer._design_options import DesignOptions
from brdf_infer._outdir import check_output_dir
from brdf_infer._outlock import writing


def add_design_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``brdf-infer design``."""
    defaults = DesignOptions()
    parser.add_argument("run_dir", help="directory of a posterior run (posterior.nc, ...)")
    parser.add_argument(
        "--scene", help="check the run is of this scene (default: the run's own scene file)"
    )
    parser.add_argument(
        "--target",
        default="tis:70",
        help="what to shrink: tis:THETA, pi_brdf0, a parameter (brdf0, a1, a2, a3, alpha, "
        "theta_s0), brdf:THETA_I,THETA_S or all (expected information gain)",
    )
    parser.add_argument(
        "--candidates",
        default="grid",
        help="grid (the scene's [design] range) or a CSV of settings "
        "(theta_i_deg, theta_s_deg[, series, phi_s_deg])",
    )
    parser.add_argument(
        "--series",
        help="the series a new grid row joins (default: [design] series, else "
        "the series with the most rows)",
    )
    parser.add_argument(
        "--budget", type=int, help="rows chosen together (default: [design] budget, 3)"
    )
    parser.add_argument("--draws", type=int, default=defaults.draws, help="posterior draws used")
    parser.add_argument(
        "--simulations",
        type=int,
        default=defaults.simulations,
        help="simulated outcomes per candidate set",
    )
    parser.add_argument("--seed", type=int, default=defaults.seed, help="random seed")
    parser.add_argument("--out", help="write design.json and design.png here (default: RUN_DIR)")
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout")


def command_design(
    args: argparse.Namespace,
    table: Callable[[Sequence[str], Sequence[Sequence[str]]], str],
    progress: Callable[[str], None],
) -> None:
    """Run ``brdf-infer design`` (every option checked before any work, nothing written on
    bad input)."""
    from brdf_infer.design import (
        DESIGN_FIGURE,
        DESIGN_FILE,
        DESIGN_HEADERS,
        DesignOptions,
        design,
        design_rows,
        design_series,
        load_design_run,
        parse_target,
        read_candidates,
        write_design,
    )

    target = parse_target(args.target)
    out = check_output_dir(args.out or args.run_dir)
    run = load_design_run(Path(args.run_dir), args.scene)
    scene = run.scene
    options = DesignOptions(
        draws=args.draws,
        simulations=args.simulations,
        budget=args.budget if args.budget is not None else scene.design.budget,
        seed=args.seed,
    )
    options.check()
    series = design_series(scene, run.measurements, args.series)
    candidates = None
    if args.candidates != "grid":
        candidates = read_candidates(args.candidates, scene, run.measurements, series)
    progress(
        f"where to measure next for {target.label}, scene '{scene.name}', series {series}, "
        f"budget {options.budget} ..."
    )
    result = design(run, target, candidates, options, series)
    # into the run folder: added to a finished run (its own lock, the run stays complete);
    # elsewhere: one writer per folder
    adds = Path(out).resolve() == Path(args.run_dir).resolve()
    args.claims.enter_context(writing(out, "design", adds=adds))
    write_design(out, result)
    payload = result.as_json()
    if args.json:
        print(json.dumps(payload))
        return
    current = payload["current"]
    if current["median"] is not None:
        print(
            f"{target.label} today: {current['median']:.4g} "
            f"({current['lo95']:.4g}–{current['hi95']:.4g}), sd {current['sd']:.3g}"
        )
    print(f"chosen together (budget {options.budget}):")
    print(table(DESIGN_HEADERS, design_rows(payload)))
    print(f"{len(payload['candidates'])} candidates, {payload['seconds']:.1f} s")
    print(f"written: {out / DESIGN_FILE}, {out / DESIGN_FIGURE}")
