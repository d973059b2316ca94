"""``brdf-infer compare``: model families ranked by PSIS-LOO
(:mod:`brdf_infer.studies.compare`) with the defaults of
:class:`~brdf_infer.scene.settings.CompareSettings`."""

from __future__ import annotations

import argparse
import sys

from brdf_infer.cli._common import (
    add_nuts_arguments,
    claimed_output_dir,
    emit_json,
    headless,
    progress,
    record_from_args,
    scene_command_parser,
    table,
)
from brdf_infer.cli._options import (
    add_force_argument,
    add_instrument_argument,
    forced,
    scene_and_measurements,
)
from brdf_infer.scene.settings import CompareSettings

DEFAULT_MODELS = ("strumik2024", "abg", "harvey-shack", "lambertian", "lambertian+abg")


def add_parser(commands) -> argparse.ArgumentParser:
    """The options of ``brdf-infer compare``."""
    defaults = CompareSettings
    parser = scene_command_parser(
        commands,
        "compare",
        "rank model families (Eq. 7, ABg, Harvey–Shack, Lambertian, …) by PSIS-LOO",
    )
    parser.add_argument(
        "--models", nargs="+", default=list(DEFAULT_MODELS), help="model families to compare"
    )
    add_nuts_arguments(
        parser,
        defaults,
        helps={
            "chains": "NUTS chains per family",
            "target_accept": "NUTS target acceptance (0.9: one setting for families that "
            "diverge more easily)",
        },
    )
    parser.add_argument(
        "--no-refit",
        action="store_true",
        help="no exact refits where Pareto k exceeds its limit (0.7 from 2200 draws)",
    )
    parser.add_argument("--out", help="also write compare.json and compare.png here")
    add_force_argument(parser)
    add_instrument_argument(parser)
    parser.set_defaults(handler=main)
    return parser


def main(args: argparse.Namespace) -> int:
    """Compare the families (options checked before the scene's work starts) and print the
    ranking."""
    headless()
    from brdf_infer.report import write_comparison
    from brdf_infer.studies.compare import (
        COMPARE_FILE,
        check_family_names,
        compare_families,
    )

    names = check_family_names(args.models)
    settings = record_from_args(CompareSettings, args, refit=not args.no_refit)
    scene, measurements = scene_and_measurements(args.scene, args.instrument, args.force)
    forced(scene, measurements)
    out = claimed_output_dir(args, args.out, "compare") if args.out else None
    progress(
        f"comparing {', '.join(names)} on scene '{scene.name}' by PSIS-LOO "
        f"({settings.chains} chains × {settings.draws} draws each) ..."
    )
    result = compare_families(
        scene, measurements, names, settings, progress=not args.json and sys.stderr.isatty()
    )
    payload = result.as_json()
    if out is not None:
        write_comparison(out, result)
        payload["out"] = str(out)
    for note in result.warnings:
        progress(f"warning: {note}")
    if args.json:
        emit_json(payload)
        return 0
    print(f"PSIS-LOO comparison on scene '{scene.name}' (best first)")
    print(comparison_table(payload))
    print(f"{result.seconds:.1f} s")
    if out is not None:
        print(f"written: {out / COMPARE_FILE}, {out / 'compare.png'}")
    return 0


def tis_percent(band: dict) -> str:
    """A TIS band of the JSON (fractions) as the human tables print TIS: in percent, the
    median and its 95 % interval."""
    return "{:.2f} ({:.2f}–{:.2f})".format(*(100 * band[key] for key in ("median", "lo95", "hi95")))


def comparison_table(payload: dict) -> str:
    """The human table of ``compare``'s JSON (best first): each family's rank with its
    sampler diagnostics beside it, and a line for each family whose diagnostics fail; TIS in
    percent, as every command prints it (the JSON keeps fractions)."""
    rows = [
        [
            row["name"],
            f"{row['elpd_loo']:.1f} ± {row['se']:.1f}",
            f"{row['d_elpd']:.1f} ± {row['dse']:.1f}",
            f"{row['weight']:.2f}",
            f"{row['p_loo']:.1f}",
            f"{row['pareto_k_max']:.2f}",
            f"{row['r_hat_max']:.3f}",
            f"{row['ess_bulk_min']:.0f}",
            str(row["divergences"]),
            "ok" if row["sampler_ok"] else "FAIL",
            tis_percent(row["tis70"]),
        ]
        for row in payload["models"]
    ]
    headers = [
        "model",
        "elpd_loo ± se",
        "Δelpd ± dse",
        "weight",
        "p_loo",
        "k max",
        "R-hat max",
        "ESS bulk min",
        "div.",
        "sampler",
        "TIS(70°) [%] (95 %)",
    ]
    lines = [table(headers, rows)]
    lines += [
        f"{row['name']}: sampler diagnostics fail ({', '.join(row['sampler_failures'])}): its "
        "place in the ranking is not to be trusted"
        for row in payload["models"]
        if not row["sampler_ok"]
    ]
    return "\n".join(lines)
