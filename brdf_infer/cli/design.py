"""``brdf-infer design``: where to measure next (:mod:`brdf_infer.design`), with the defaults
of :class:`~brdf_infer.scene.settings.DesignOptions`; every option checked before any work."""

from __future__ import annotations

import argparse
from pathlib import Path

from brdf_infer._internal.outlock import writing
from brdf_infer.cli._common import (
    add_json_argument,
    command_parser,
    emit_json,
    headless,
    progress,
    table,
)
from brdf_infer.cli._outdir import check_output_dir
from brdf_infer.scene.settings import DesignOptions


def add_parser(commands) -> argparse.ArgumentParser:
    """The options of ``brdf-infer design``."""
    defaults = DesignOptions
    parser = command_parser(
        commands,
        "design",
        "where to measure next: the expected posterior sd of a target after new rows at each "
        "feasible setting, and the best K settings together",
    )
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
        "--for",
        dest="coating",
        choices=("measured", "coating", "new_part"),
        help="whose target: the sample(s) measured, the coating or a new, unmeasured part "
        "(default: the run's target; a parameter is the coating's)",
    )
    parser.add_argument(
        "--new-sample",
        action="store_true",
        help="the new rows go on one physical sample not yet measured (is another sample "
        "worth more than another angle?)",
    )
    parser.add_argument(
        "--candidates",
        default="grid",
        help="grid (the scene's [design] range) or a CSV of settings "
        "(theta_i_deg, theta_s_deg[, series, phi_s_deg])",
    )
    parser.add_argument(
        "--series",
        help="the series a new grid row is taken in (default: --same-session, else [design] "
        "series, else the series with the most rows); one without rows is a new series, its "
        "aperture from [series.NAME] or --aperture",
    )
    parser.add_argument(
        "--same-session",
        metavar="SERIES",
        help="new rows of SERIES continue its measured session (its reference measurement and "
        "rotation settings; default: [design] same_session, else every new row is a new "
        "session with a reference of its own)",
    )
    parser.add_argument(
        "--aperture",
        metavar="D_MM,R_MM",
        help="aperture diameter and aperture-sample distance [mm] of a new series",
    )
    parser.add_argument(
        "--budget",
        type=int,
        help=f"rows chosen together (default: [design] budget, {defaults.budget})",
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
    add_json_argument(parser)
    parser.set_defaults(handler=main)
    return parser


def main(args: argparse.Namespace) -> int:
    """Run ``brdf-infer design`` (every option checked before any work, nothing written on
    bad input) and print the chosen settings."""
    headless()
    from brdf_infer.design import (
        DESIGN_FIGURE,
        DESIGN_FILE,
        DESIGN_HEADERS,
        current_words,
        design,
        design_coating,
        design_rows,
        design_series,
        load_design_run,
        parse_target,
        reach_line,
        read_candidates,
        session_scene,
        write_design,
    )
    from brdf_infer.errors import BadInputError
    from brdf_infer.verdict import TARGET_WORDS

    target = parse_target(args.target)
    out = check_output_dir(args.out or args.run_dir, option="--out")
    run = load_design_run(Path(args.run_dir), args.scene)
    scene = run.scene
    options = DesignOptions(
        draws=args.draws,
        simulations=args.simulations,
        budget=args.budget if args.budget is not None else scene.design.budget,
        seed=args.seed,
    )
    try:
        coating = design_coating(target, run, args.coating)
    except BadInputError as error:
        raise BadInputError(error.problem, file=error.file, field="--for") from None
    aperture = _aperture(args.aperture)
    same_session = args.same_session or scene.design.same_session
    series = design_series(scene, run.measurements, args.series, same_session, aperture)
    candidates = None
    if args.candidates != "grid":
        scene_ = session_scene(scene, series, aperture)
        candidates = read_candidates(args.candidates, scene_, run.measurements, series)
    session = "new sessions" if same_session is None else f"series {same_session}'s session"
    progress(
        f"where to measure next for {target.label} of {TARGET_WORDS[coating]}, scene "
        f"'{scene.name}', series {series}{', a new sample' if args.new_sample else ''}, "
        f"{session}, budget {options.budget} ..."
    )
    result = design(
        run, target, candidates, options, series, same_session, aperture, coating, args.new_sample
    )
    # into the run folder: added to a finished run (its own lock, the run stays complete);
    # elsewhere: one writer per folder
    adds = Path(out).resolve() == Path(args.run_dir).resolve()
    args.claims.enter_context(writing(out, "design", option="--out", adds=adds))
    write_design(out, result)
    payload = result.as_json()
    if args.json:
        emit_json(payload)
        return 0
    current = current_words(payload)
    if current is not None:  # in the table's unit: TIS and π·BRDF0 in per cent
        print(f"{target.label} of {TARGET_WORDS[coating]} today: {current}")
    print(f"chosen together (budget {options.budget}):")
    print(table(DESIGN_HEADERS, design_rows(payload)))
    print(reach_line(payload))
    print(f"{len(payload['candidates'])} candidates, {payload['seconds']:.1f} s")
    print(f"written: {out / DESIGN_FILE}, {out / DESIGN_FIGURE}")
    return 0


def _aperture(text: str | None) -> tuple[float, float] | None:
    """``--aperture D_MM,R_MM`` as (diameter, distance) [mm]."""
    from brdf_infer.errors import BadInputError

    if text is None:
        return None
    try:
        diameter, distance = (float(part) for part in text.split(","))
    except ValueError:
        raise BadInputError(
            f"expected D_MM,R_MM (two numbers), got {text!r}", field="--aperture"
        ) from None
    if not 0 < diameter < distance < float("inf"):
        raise BadInputError(
            f"expected 0 < diameter < distance [mm], got {text!r}", field="--aperture"
        )
    return diameter, distance
