"""``brdf-infer fit``: the paper's regression (Sec. 4.2), its grid search over (α, θs0), or
least squares of any model family over its free parameters (:mod:`brdf_infer.fit.lsq`)."""

from __future__ import annotations

import argparse
import math
import time
from typing import Any

import numpy as np

from brdf_infer.cli._common import emit_json, progress, scene_command_parser, table
from brdf_infer.cli._options import (
    add_force_argument,
    add_instrument_argument,
    add_model_argument,
    forced,
    scene_and_measurements,
)
from brdf_infer.errors import BadInputError
from brdf_infer.scene.settings import LSQ_STARTS, check_family_name

UNITS = {
    "brdf0": "sr^-1",
    "a1": "deg^-2",
    "a2": "deg^(-1-alpha)",
    "a3": "deg^(-2-alpha)",
    "alpha": "-",
    "theta_s0": "deg",
}


def add_parser(commands) -> argparse.ArgumentParser:
    """The options of ``brdf-infer fit``."""
    parser = scene_command_parser(
        commands,
        "fit",
        "fit the paper's regression of Eq. (7), or least squares of any model family",
    )
    parser.add_argument("--method", choices=["paper", "lsq"], default="paper", help="fit method")
    add_model_argument(parser)
    add_instrument_argument(parser)
    parser.add_argument("--starts", type=int, default=LSQ_STARTS, help="lsq: number of starts")
    parser.add_argument(
        "--solver", choices=["lm", "gauss-newton", "dogleg"], default="lm", help="lsq: solver"
    )
    parser.add_argument("--seed", type=int, default=0, help="lsq: seed of the starting points")
    parser.add_argument(
        "--scale-covariance", action="store_true", help="lsq: scale covariance by reduced chi2"
    )
    parser.add_argument("--selection", help="data selection for --method paper (default: scene's)")
    parser.add_argument("--grid", action="store_true", help="grid search over (alpha, theta_s0)")
    add_force_argument(parser)
    parser.set_defaults(handler=main)
    return parser


def main(args: argparse.Namespace) -> int:
    """Fit, check the fit's plausibility and print it."""
    from brdf_infer.model import family
    from brdf_infer.verdict.plausibility import require_plausible
    from brdf_infer.workflow import fit_checks

    check_family_name(args.model)
    scene, measurements = scene_and_measurements(args.scene, args.instrument, args.force)
    passed = forced(scene, measurements)
    model = args.model or scene.model.family
    member = family(model, scene.model.fold, scene.model.constants)
    if not member.paper_parameters and args.method != "lsq":
        raise BadInputError(
            f"the paper's regression is Eq. (7)'s; fit {model} with --method lsq",
            field="--model",
        )
    payload = _fit(args, scene, measurements, member)
    implausible = fit_checks(scene, measurements, payload)
    require_plausible(implausible, args.force)
    payload["implausible"] = passed + [found.record for found in implausible]
    for found in implausible:
        progress(f"warning: forced past a plausibility check: {found.record}")
    if args.json:
        emit_json(payload)
    elif args.method == "lsq":
        _print_lsq(payload)
        print(f"fit quality: {payload['fit_quality']}")
    else:
        _print_paper_fit(scene.name, payload)
    return 0


def _fit(args: argparse.Namespace, scene, measurements, member) -> dict[str, Any]:
    """The fit's JSON: the family's least squares, or for Eq. (7) the paper's regression (or
    its grid search)."""
    if args.method == "lsq":
        from brdf_infer.workflow import lsq_summary

        return lsq_summary(
            scene,
            measurements,
            member,
            starts=args.starts,
            solver=args.solver,
            seed=args.seed,
            scale_covariance=args.scale_covariance,
            progress=progress,
        )
    if args.grid:
        return _grid_payload(scene, measurements, args.selection)
    from brdf_infer.workflow import paper_fit_summary

    return paper_fit_summary(scene, measurements, args.selection)


def _sigma_table(payload: dict[str, Any]) -> str:
    """Parameters with the unscaled 1σ and the 1σ scaled by sqrt(chi2/dof), side by side."""
    factor = math.sqrt(payload["chi2_dof"]) if payload.get("covariance_scaled") else 1.0
    flat = "flat profile: none"  # the data constrain it less than its prior (fit.lsq)
    rows = [
        [
            name,
            f"{value:.4g}",
            flat if payload["sigma"][name] is None else f"{payload['sigma'][name] / factor:.2g}",
            flat
            if payload["sigma_scaled"][name] is None
            else f"{payload['sigma_scaled'][name]:.2g}",
        ]
        for name, value in payload["params"].items()
    ]
    return table(["parameter", "value", "1 sigma", "1 sigma x sqrt(chi2/dof)"], rows)


def _print_lsq(payload: dict[str, Any]) -> None:
    print(
        f"least-squares fit of {payload['model']} to scene '{payload['scene']}' "
        f"({payload['solver']})"
    )
    print(_sigma_table(payload))
    paper = "paper_fit_cost" in payload  # Eq. (7)'s family: the paper fit's χ² beside
    print(
        table(
            [
                "points",
                "dof",
                "chi2",
                *(["chi2 (paper fit)"] if paper else []),
                "cond(J)",
                "starts at best",
                "time [s]",
            ],
            [
                [
                    str(payload["n_points"]),
                    str(payload["dof"]),
                    f"{payload['cost']:.4f}",
                    *([f"{payload['paper_fit_cost']:.4f}"] if paper else []),
                    f"{payload['condition_number']:.2g}",
                    f"{payload['starts_converged']}/{payload['starts']}",
                    f"{payload['seconds']:.3f} (+{payload['compile_seconds']:.1f} compile)",
                ]
            ],
        )
    )
    names = list(payload["params"])
    correlation = payload["correlation"]
    print("correlation:")
    print(
        table(
            ["", *names],
            [[a, *(f"{c:+.2f}" for c in row)] for a, row in zip(names, correlation, strict=True)],
        )
    )


def _print_paper_fit(scene_name: str, payload: dict[str, Any]) -> None:
    print(f"paper fit (Sec. 4.2) of scene '{scene_name}', selection '{payload['selection']}'")
    rows = [[k, f"{v:.4g}", UNITS[k]] for k, v in payload["params"].items()]
    print(table(["parameter", "value", "unit"], rows))
    print(
        table(
            ["points", "sigma_E [%]", "sigma_RE [%]", "time [s]"],
            [
                [
                    str(payload["n_points"]),
                    f"{100 * payload['sigma_e']:.2f}",
                    f"{100 * payload['sigma_re']:.2f}",
                    f"{payload['seconds']:.3f}",
                ]
            ],
        )
    )
    if "sigma_tre" in payload:
        print(f"grid search: least total relative error {100 * payload['sigma_tre']:.2f} %")


def _grid_payload(scene, measurements, selection: str | None) -> dict[str, Any]:
    from brdf_infer.fit.paper import paper_grid_search
    from brdf_infer.model.params import params_to_dict

    alphas = np.arange(1.5, 8.01, 0.25)
    theta_s0s = np.arange(-40.0, 10.01, 2.0)
    progress(f"grid search over {alphas.size} x {theta_s0s.size} (alpha, theta_s0) ...")
    start = time.perf_counter()
    grid = paper_grid_search(scene, measurements, alphas, theta_s0s, selection=selection)
    seconds = time.perf_counter() - start
    best = grid.best
    return {
        "method": "paper",
        "scene": scene.name,
        "selection": selection or scene.paper_fit.selection,
        "params": params_to_dict(best.params),
        "sigma_e": best.sigma_e,
        "sigma_re": best.sigma_re,
        "sigma_tre": float(grid.sigma_tre.min()),
        "n_points": best.n_points,
        "grid": {"alpha": alphas.tolist(), "theta_s0": theta_s0s.tolist()},
        "seconds": seconds,
    }
