"""Command line ``brdf-infer`` (also ``python -m brdf_infer``).

Each subcommand takes a scene (built-in name or TOML path; default ``lya``). With ``--json``
stdout holds exactly one JSON object; progress goes to stderr. Bad input prints one line on
stderr and exits with code 2.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import signal
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from brdf_infer._cli_compare import add_compare_arguments, command_compare
from brdf_infer._cli_design import add_design_arguments, command_design
from brdf_infer._cli_export import add_export_arguments, command_export
from brdf_infer._cli_fold import add_fold_arguments, chosen_fold, refuse_fold
from brdf_infer._cli_sensitivity import add_sensitivity_arguments, command_sensitivity
from brdf_infer._device import DEVICES, placement
from brdf_infer._outdir import claim_output_dir
from brdf_infer.errors import BadInputError

EXIT_BAD_INPUT = 2


class _Parser(argparse.ArgumentParser):
    """argparse that reports a usage error in one line (exit code 2)."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see --help)\n")


def _headless() -> None:
    """Figures are written to files, never shown: the non-interactive backend, set here and
    not on import, so that notebooks keep their inline figures."""
    import matplotlib

    matplotlib.use("Agg")


def _progress(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def _emit_json(content: dict[str, Any]) -> None:
    print(json.dumps(content))


def _scene_and_measurements(name: str, instrument: str | None = None, force: bool | None = None):
    """The scene (every file it names checked; predicting through ``instrument`` when given)
    and its rows, checked for plausibility (:mod:`brdf_infer.plausibility`): a failed check
    stops the command unless ``force`` (:func:`_forced` then reports it); a command without
    ``--force`` (``force=None``) only warns. Other warnings on stderr."""
    from brdf_infer.plausibility import measurement_checks, measurement_warnings, require_plausible
    from brdf_infer.scene import check_instrument, load_scene

    _checked_instrument(instrument)
    scene = load_scene(name)
    if instrument is not None:
        scene = check_instrument(scene, instrument)
    measurements = scene.load_measurements()
    implausible = measurement_checks(scene, measurements)
    if force is None:
        warnings = [found.message for found in implausible]
    else:
        require_plausible(implausible, force)
        warnings = []
    for warning in warnings + measurement_warnings(measurements):
        _progress(f"warning: {warning}")
    return scene, measurements


def _forced(scene, measurements) -> list[str]:
    """The input checks a ``--force`` command goes past, one line each (also on stderr)."""
    from brdf_infer.plausibility import measurement_checks

    lines = [found.record for found in measurement_checks(scene, measurements)]
    for line in lines:
        _progress(f"warning: forced past a plausibility check: {line}")
    return lines


def _force_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--force",
        action="store_true",
        help="go on past a failed plausibility check (values that look like percent, angles "
        "that look like radians, a fit whose pi*BRDF0 or TIS exceeds 1); the verdict then "
        "names it",
    )


def _checked_model(name: str | None) -> None:
    """``--model``: a known family (checked before the scene is read)."""
    from brdf_infer.model import FAMILY_NAMES

    if name is not None and name not in FAMILY_NAMES:
        raise BadInputError(
            f"unknown model family {name!r} (known: {', '.join(FAMILY_NAMES)})", field="--model"
        )


def _model_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--model",
        help="model family: strumik2024, abg, harvey-shack, lambertian, lambertian+abg "
        "(default: the scene's [model] family)",
    )


def _table(headers: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(headers)]
    lines = ["  ".join(h.rjust(w) for h, w in zip(headers, widths, strict=True))]
    lines.append("  ".join("-" * w for w in widths))
    lines += ["  ".join(c.rjust(w) for c, w in zip(row, widths, strict=True)) for row in rows]
    return "\n".join(lines)


# --------------------------------------------------------------------------- fit


def _print_params_table(params: dict[str, float]) -> None:
    units = {
        "brdf0": "sr^-1",
        "a1": "deg^-2",
        "a2": "deg^(-1-alpha)",
        "a3": "deg^(-2-alpha)",
        "alpha": "-",
        "theta_s0": "deg",
    }
    print(
        _table(
            ["parameter", "value", "unit"], [[k, f"{v:.4g}", units[k]] for k, v in params.items()]
        )
    )


def _sigma_table(payload: dict[str, Any], digits: int = 4) -> str:
    """Parameters with the unscaled 1σ and the 1σ scaled by sqrt(chi2/dof), side by side."""
    factor = math.sqrt(payload["chi2_dof"]) if payload.get("covariance_scaled") else 1.0
    rows = [
        [
            name,
            f"{value:.{digits}g}",
            f"{payload['sigma'][name] / factor:.2g}",
            f"{payload['sigma_scaled'][name]:.2g}",
        ]
        for name, value in payload["params"].items()
    ]
    return _table(["parameter", "value", "1 sigma", "1 sigma x sqrt(chi2/dof)"], rows)


def _print_fit_quality(payload: dict[str, Any]) -> None:
    print(f"fit quality: {payload['fit_quality']}")


def _print_lsq(payload: dict[str, Any]) -> None:
    print(f"least-squares fit of scene '{payload['scene']}' ({payload['solver']})")
    print(_sigma_table(payload))
    print(
        _table(
            ["points", "chi2", "chi2 (paper fit)", "cond(J)", "starts at best", "time [s]"],
            [
                [
                    str(payload["n_points"]),
                    f"{payload['cost']:.4f}",
                    f"{payload['paper_fit_cost']:.4f}",
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
        _table(
            ["", *names],
            [[a, *(f"{c:+.2f}" for c in row)] for a, row in zip(names, correlation, strict=True)],
        )
    )


def _command_fit(args: argparse.Namespace) -> None:
    from brdf_infer.model import FAMILY_NAMES, REFERENCE_FAMILY, family
    from brdf_infer.plausibility import require_plausible
    from brdf_infer.workflow import fit_checks

    if args.model is not None and args.model not in FAMILY_NAMES:
        raise BadInputError(
            f"unknown model family {args.model!r} (known: {', '.join(FAMILY_NAMES)})",
            field="--model",
        )
    scene, measurements = _scene_and_measurements(args.scene, args.instrument, args.force)
    forced = _forced(scene, measurements)
    args.model = args.model or scene.model.family
    if args.model != REFERENCE_FAMILY and args.method != "lsq":
        raise BadInputError(
            f"the paper's regression is Eq. (7)'s; fit {args.model} with --method lsq",
            field="--model",
        )
    if args.model != REFERENCE_FAMILY:
        from brdf_infer.family_fit import fit_family_lsq

        _progress(f"least squares of {args.model}: {args.starts} starts ...")
        payload = fit_family_lsq(
            scene, measurements, family(args.model), starts=args.starts, seed=args.seed
        ).as_json(scene.name)
    elif args.method == "lsq":
        from brdf_infer.workflow import lsq_summary

        payload = lsq_summary(
            scene,
            measurements,
            starts=args.starts,
            solver=args.solver,
            seed=args.seed,
            scale_covariance=args.scale_covariance,
            progress=_progress,
        )
    elif args.grid:
        payload = _grid_payload(scene, measurements, args.selection)
    else:
        from brdf_infer.workflow import paper_fit_summary

        payload = paper_fit_summary(scene, measurements, args.selection)
    implausible = fit_checks(scene, measurements, payload)
    require_plausible(implausible, args.force)
    payload["implausible"] = forced + [found.record for found in implausible]
    for found in implausible:
        _progress(f"warning: forced past a plausibility check: {found.record}")
    if args.json:
        _emit_json(payload)
    elif args.model != REFERENCE_FAMILY:
        print(f"least-squares fit of {args.model} to scene '{scene.name}'")
        print(_sigma_table(payload, digits=6))
        print(
            f"chi2 = {payload['cost']:.2f} for {payload['n_points']} points "
            f"({payload['dof']} dof) in {payload['seconds']:.1f} s"
        )
        _print_fit_quality(payload)
    elif args.method == "lsq":
        _print_lsq(payload)
        _print_fit_quality(payload)
    else:
        _print_paper_fit(scene.name, payload)


def _print_paper_fit(scene_name: str, payload: dict[str, Any]) -> None:
    print(f"paper fit (Sec. 4.2) of scene '{scene_name}', selection '{payload['selection']}'")
    _print_params_table(payload["params"])
    print(
        _table(
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
    from brdf_infer.paper_fit import paper_grid_search
    from brdf_infer.params import params_to_dict

    alphas = np.arange(1.5, 8.01, 0.25)
    theta_s0s = np.arange(-40.0, 10.01, 2.0)
    _progress(f"grid search over {alphas.size} x {theta_s0s.size} (alpha, theta_s0) ...")
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


# --------------------------------------------------------------------------- tis / brdf


def _timed(function, *args, **kwargs):
    """(result, seconds of the first call incl. compilation, seconds of a second call)."""
    import jax

    start = time.perf_counter()
    result = jax.block_until_ready(function(*args, **kwargs))
    first = time.perf_counter() - start
    start = time.perf_counter()
    jax.block_until_ready(function(*args, **kwargs))
    return result, first, time.perf_counter() - start


def _command_tis(args: argparse.Namespace) -> None:
    from brdf_infer.model import fold_statement, tis_with_error
    from brdf_infer.params import resolve_params

    theta_i = _angles(args.theta_i, "--theta-i", 0.0, 90.0, upper_open=True)
    if args.run is not None:
        _tis_from_run(args, theta_i)
        return
    args.params = args.params or "uv-paper"
    params = resolve_params(args.params)
    fold = chosen_fold(args.fold)
    (values, errors), first, second = _timed(tis_with_error, theta_i, params, fold=fold)
    values, errors = np.asarray(values), np.asarray(errors)
    warnings = _tis_warnings(theta_i, values)
    for warning in warnings:
        _progress(f"warning: {warning}")
    if args.json:
        _emit_json(
            {
                "theta_i_deg": theta_i.tolist(),
                "tis": values.tolist(),
                "abs_error": errors.tolist(),
                "fold": fold,
                "warnings": warnings,
                "seconds": second,
                "compile_seconds": first - second,
            }
        )
        return
    print(f"TIS, Eq. (9), parameters '{args.params}'; {fold_statement(fold)}")
    rows = [
        [f"{t:g}", f"{100 * v:.4f}", f"{e:.1e}"]
        for t, v, e in zip(theta_i, values, errors, strict=True)
    ]
    print(_table(["theta_i [deg]", "TIS [%]", "quadrature error [-]"], rows))
    print(
        f"time: {1e3 * second:.2f} ms for {theta_i.size} angles (+{first - second:.2f} s compile)"
    )


def _tis_warnings(theta_i: np.ndarray, values: np.ndarray) -> list[str]:
    """TIS above 1 means more power scattered than incident: the parameters are unphysical."""
    unphysical = theta_i[np.asarray(values) > 1.0]
    if unphysical.size == 0:
        return []
    angles = ", ".join(f"{t:g}" for t in unphysical)
    return [f"TIS > 1 at theta_i = {angles} deg: these parameters are not physical"]


TIS_RUN_FAMILY_DRAWS = 1000  # a lobe family's TIS is a 2-D quadrature (≈ 1 ms each)


def _tis_from_run(args: argparse.Namespace, theta_i: np.ndarray) -> None:
    from brdf_infer.model import REFERENCE_FAMILY, fold_statement
    from brdf_infer.posterior import family_tis_band, load_run_draws, load_run_family, tis_band

    start = time.perf_counter()
    member, physical = load_run_family(Path(args.run))
    if member.name == REFERENCE_FAMILY:
        params, run_fold, constants = load_run_draws(Path(args.run))
        fold = chosen_fold(args.fold, run_fold)
        band = {
            **tis_band(params, theta_i, fold, constants),
            "draws": int(np.size(params.brdf0)),
        }
        what = "Eq. (9)"
    else:
        refuse_fold(args.fold, member.name)
        fold = False
        band = family_tis_band(member, physical, theta_i, TIS_RUN_FAMILY_DRAWS)
        what = member.name
    seconds = time.perf_counter() - start
    if args.json:
        _emit_json({**band, "model": member.name, "fold": fold, "seconds": seconds})
        return
    print(f"TIS, {what}, over {band['draws']} posterior draws of {args.run}")
    print(fold_statement(fold))
    rows = [
        [f"{t:g}", *(f"{100 * band[k][i]:.3f}" for k in ("median", "lo68", "hi68", "lo95", "hi95"))]
        for i, t in enumerate(theta_i)
    ]
    headers = ["theta_i [deg]", "median [%]", "16 % [%]", "84 % [%]", "2.5 % [%]", "97.5 % [%]"]
    print(_table(headers, rows))
    print(f"time: {seconds:.2f} s")


def _command_posterior(args: argparse.Namespace) -> None:
    from brdf_infer.posterior import run_posterior

    _checked_model(args.model)
    scene, measurements = _scene_and_measurements(args.scene, args.instrument, args.force)
    forced = _forced(scene, measurements)
    out = claim_output_dir(
        args.out or Path("reports") / scene.name / args.sampler, "posterior", args.claims
    )
    if args.warmup is None:
        args.warmup = 1000 if args.sampler == "nuts" else 4000
    run = run_posterior(
        scene,
        measurements,
        sampler=args.sampler,
        chains=args.chains,
        draws=args.draws,
        warmup=args.warmup,
        walkers=args.walkers,
        steps=args.steps,
        seed=args.seed,
        out=out,
        resume=args.resume,
        error_model=args.error_model,
        model=args.model,
        target_accept=args.target_accept,
        announce=lambda what: _progress(what + " ..."),
        forced=forced,
    )
    summary = run.summary
    if args.json:
        _emit_json({"out": str(out), **summary})
        return
    _print_posterior_summary(summary, out)
    _print_verdict(summary["verdict"])


def _print_verdict(verdict: dict[str, Any]) -> None:
    """The run's one verdict (:mod:`brdf_infer.verdict`), as its report shows it."""
    print(f"verdict: {verdict['text']}")


def _print_posterior_summary(summary: dict[str, Any], out: Path) -> None:
    diagnostics = summary["diagnostics"]
    rows = [
        [
            name,
            f"{values['mean']:.4g}",
            f"{values['sd']:.2g}",
            f"{values['r_hat']:.3f}",
            f"{values['ess_bulk']:.0f}",
            f"{values['ess_tail']:.0f}",
        ]
        for name, values in diagnostics["parameters"].items()
    ]
    print(
        f"posterior of scene '{summary['scene']}', model {summary['model']} ({summary['sampler']})"
    )
    print(_table(["parameter", "mean", "sd", "R-hat", "ESS bulk", "ESS tail"], rows))
    tis70 = summary["tis_70deg"]
    if tis70 is not None:
        print(
            f"TIS(70 deg) = {100 * tis70['median']:.2f} % "
            f"(95 %: {100 * tis70['lo95']:.2f}-{100 * tis70['hi95']:.2f} %; "
            f"{'with' if summary['fold'] else 'without'} Eq. (10) folding)"
        )
    seconds = summary["seconds"]
    print(
        f"sampling {seconds['sampling']:.1f} s, total {seconds['total']:.1f} s; results in {out}/"
    )


def _angles(values, option: str, low: float, high: float, upper_open: bool = False) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    bad = ~np.isfinite(array) | (array < low) | ((array >= high) if upper_open else (array > high))
    if bad.any():
        bracket = ")" if upper_open else "]"
        raise BadInputError(
            f"{array[bad][0]:g} deg is outside [{low:g}, {high:g}{bracket}", field=option
        )
    return array


def _command_export(args: argparse.Namespace) -> None:
    command_export(args, _angles, _table, _progress)


def _command_compare(args: argparse.Namespace) -> None:
    _headless()

    def scene_and_measurements(name: str):
        scene, measurements = _scene_and_measurements(name, args.instrument, args.force)
        _forced(scene, measurements)
        return scene, measurements

    command_compare(args, scene_and_measurements, _table, _progress)


def _command_design(args: argparse.Namespace) -> None:
    _headless()
    command_design(args, _table, _progress)


def _command_sensitivity(args: argparse.Namespace) -> None:
    _headless()
    command_sensitivity(args, _scene_and_measurements, _table, _progress)


def _command_brdf(args: argparse.Namespace) -> None:
    from brdf_infer.model import brdf_hemisphere, brdf_inplane
    from brdf_infer.params import resolve_params

    params = resolve_params(args.params)
    theta_i = _angles(args.theta_i, "--theta-i", 0.0, 90.0, upper_open=True)
    if args.phi is None:
        theta_s = _angles(args.theta_s, "--theta-s", -90.0, 90.0)
        phi = None
    else:
        theta_s = _angles(args.theta_s, "--theta-s", 0.0, 90.0)
        phi = _angles(args.phi, "--phi", 0.0, 360.0, upper_open=True)
    arrays = [theta_i, theta_s] + ([] if phi is None else [phi])
    try:
        arrays = np.broadcast_arrays(*arrays)
    except ValueError:
        raise BadInputError(
            "--theta-i, --theta-s and --phi need equal lengths (or length 1)", field="--theta-s"
        ) from None
    fold = chosen_fold(args.fold)
    if phi is None:
        values = brdf_inplane(arrays[0], arrays[1], params, fold=fold)
    else:
        values = brdf_hemisphere(arrays[0], arrays[1], arrays[2], params, fold=fold)
    payload = {
        "theta_i_deg": arrays[0].tolist(),
        "theta_s_deg": arrays[1].tolist(),
        "brdf": np.asarray(values).tolist(),
        "fold": fold,
    }
    if phi is not None:
        payload["phi_deg"] = arrays[2].tolist()
    if args.json:
        _emit_json(payload)
        return
    headers = ["theta_i [deg]", "theta_s [deg]" if phi is None else "theta [deg]"]
    headers += [] if phi is None else ["phi [deg]"]
    rows = [
        [f"{v:g}" for v in column] + [f"{b:.4e}"]
        for *column, b in zip(*arrays, payload["brdf"], strict=True)
    ]
    print(_table([*headers, "BRDF [sr^-1]"], rows))


# --------------------------------------------------------------------------- scenes / run


def _command_scenes(args: argparse.Namespace) -> None:
    from brdf_infer.scene import BUILTIN_SCENES, load_scene

    scenes = [load_scene(name) for name in BUILTIN_SCENES]
    entries = [{"name": s.name, "description": s.description, "path": str(s.path)} for s in scenes]
    if args.json:
        _emit_json({"scenes": entries})
        return
    print(_table(["scene", "description"], [[e["name"], e["description"]] for e in entries]))


def _command_run(args: argparse.Namespace) -> None:
    _headless()
    from brdf_infer.workflow import RunSettings, run

    _checked_model(args.model)
    # the input checks stop here, the fits' in run(); run() reports what it is forced past
    scene, measurements = _scene_and_measurements(args.scene, args.instrument, args.force)
    settings = RunSettings(
        chains=args.chains,
        draws=args.draws,
        warmup=args.warmup,
        seed=args.seed,
        model=args.model,
        studies=_requested_studies(args, scene),
        force=args.force,
    )
    _checked_settings(settings)
    out = claim_output_dir(args.out or Path("reports") / scene.name, "run", args.claims)
    result = run(
        scene,
        measurements,
        out,
        settings,
        example=Path(args.example) if args.example else None,
        progress=_progress,
    )
    if args.json:
        _emit_json(result.as_json())
        return
    paper, lsq = result.paper_fit, result.lsq
    print(f"scene '{scene.name}': {len(measurements)} measurements, model {result.model}")
    if paper is not None:
        print(
            f"paper fit: sigma_E = {100 * paper['sigma_e']:.2f} % on {paper['n_points']} points "
            f"(selection '{paper['selection']}')"
        )
    print(
        f"least squares: chi2 = {lsq['cost']:.2f} for {lsq['n_points']} points "
        f"({lsq['starts_converged']}/{lsq['starts']} starts at the optimum); "
        f"fit quality {lsq['fit_quality']}"
    )
    _print_posterior_summary(result.posterior, out)
    if result.comparison is not None:
        best = result.comparison["models"][0]
        untrusted = [m["name"] for m in result.comparison["models"] if not m["sampler_ok"]]
        caveat = (
            f"; sampler diagnostics fail for {', '.join(untrusted)}: not to be trusted in the "
            "ranking"
            if untrusted
            else ""
        )
        print(f"model comparison: {best['name']} first (PSIS-LOO, see the report){caveat}")
    _print_verdict(result.verdict.as_json())
    print(f"report: {result.report}")
    print(f"done in {result.seconds:.1f} s")


_RUN_FLAGS = {"chains": "--chains", "draws": "--draws", "warmup": "--warmup"}


def _checked_settings(settings) -> None:
    """``settings.check()`` with the record's field names mapped to this command's flags."""
    try:
        settings.check()
    except BadInputError as error:
        flag = _RUN_FLAGS.get(error.field or "")
        if flag is None:
            raise
        raise BadInputError(error.problem, field=flag) from None


def _requested_studies(args: argparse.Namespace, scene):
    """The studies the options ask for (None: none given, the scene's ``[studies]``)."""
    from brdf_infer.error_model import ERROR_MODELS
    from brdf_infer.instrument import INSTRUMENT_MODELS
    from brdf_infer.model import FAMILY_NAMES
    from brdf_infer.scene import Studies
    from brdf_infer.workflow import full_studies

    if args.full:
        return full_studies(scene)
    given = (args.error_models, args.instruments, args.compare)
    if all(value is None for value in given) and not (args.raytrace or args.sensitivity):
        return None
    for option, values, known in (
        ("--error-models", args.error_models, ERROR_MODELS),
        ("--instruments", args.instruments, INSTRUMENT_MODELS),
        ("--compare", args.compare, FAMILY_NAMES),
    ):
        for value in values or ():
            if value not in known:
                raise BadInputError(
                    f"unknown name {value!r} (known: {', '.join(known)})", field=option
                )
    if args.compare is not None and len(set(args.compare)) < 2:
        raise BadInputError("name at least two families to compare", field="--compare")
    if args.raytrace and scene.raytrace is None:
        raise BadInputError(
            "the scene has no [raytrace] table to ray-trace with",
            file=scene.path,
            field="--raytrace",
        )
    return Studies(
        error_models=tuple(args.error_models or ()),
        instruments=tuple(args.instruments or ()),
        raytrace=args.raytrace,
        compare=tuple(dict.fromkeys(args.compare or ())),
        sensitivity=args.sensitivity,
    )


def _require_raytrace(scene) -> None:
    if scene.raytrace is None:
        raise BadInputError(
            "this scene has no [raytrace] table (the measurement setup of Sec. 6)",
            file=scene.path,
            field="raytrace",
        )


def _command_raytrace(args: argparse.Namespace) -> None:
    _headless()
    from brdf_infer.raytrace import raytrace_payload, raytrace_posterior_payload, thin_draws
    from brdf_infer.scene import load_scene
    from brdf_infer.workflow import RUN_TRACE_BAND_RAYS

    scene = load_scene(args.scene)
    _require_raytrace(scene)
    for option, value, low in (("--rays", args.rays, 1), ("--draws", args.draws, 2)):
        if value is not None and value < low:
            raise BadInputError(f"{option} must be at least {low}, got {value}")
    measurements = scene.load_measurements()
    out = claim_output_dir(args.out, "raytrace", args.claims) if args.out else None
    progress = None if args.json else _progress
    if args.run is not None:
        from brdf_infer.posterior import load_run_draws

        all_draws, _, _ = load_run_draws(Path(args.run))
        payload = raytrace_posterior_payload(
            scene,
            measurements,
            thin_draws(all_draws, args.draws),
            f"posterior of {args.run}",
            rays=args.rays or RUN_TRACE_BAND_RAYS,
            seed=args.seed,
            progress=progress,
        )
    else:
        from brdf_infer.params import resolve_params

        name = args.params or scene.outputs.reference_params or "uv-paper"
        payload = raytrace_payload(
            scene,
            measurements,
            resolve_params(name),
            name,
            rays=args.rays,
            seed=args.seed,
            estimator=args.estimator,
            progress=progress,
        )
    for warning in payload["warnings"]:
        _progress(f"warning: {warning}")
    if out is not None:
        _write_raytrace(out, scene, measurements, payload)
    if args.json:
        _emit_json(payload)
        return
    _print_raytrace(payload)


def _write_raytrace(out: Path, scene, measurements, payload: dict) -> None:
    from brdf_infer._atomic import atomic_write_bytes, atomic_write_json
    from brdf_infer.params import Params
    from brdf_infer.raytrace import simulate_images
    from brdf_infer.report import figure_png, plot_detector_images, plot_raytrace

    out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(out / "raytrace.json", {"traces": [payload]})
    atomic_write_bytes(out / "raytrace.png", figure_png(plot_raytrace([payload])))
    params = Params(**payload["params"])
    images = simulate_images(scene, measurements, params, seed=payload["seed"])
    atomic_write_bytes(out / "detector_images.png", figure_png(plot_detector_images(images)))
    _progress(f"wrote raytrace.json, raytrace.png and detector_images.png in {out}")


def _print_raytrace(payload: dict) -> None:
    print(
        f"series {payload['series']} ray traced with '{payload['params_source']}': "
        f"{payload['rays']} rays per configuration, {payload['estimator']} estimator"
    )
    headers = [
        "theta_i [deg]",
        "delta [deg]",
        "measured",
        "simulated",
        "MC error",
        "point Eq. (6)",
        "sim/meas",
        "image ratio",
    ]
    if payload["draws"]:
        headers.insert(5, "95 % band")
    rows = []
    for row in payload["rows"]:
        cells = [
            f"{row['theta_i_deg']:g}",
            f"{row['delta_deg']:+g}",
            f"{row['measured']:.3e}",
            f"{row['simulated']:.3e}",
            f"{100 * row['mc_se'] / row['simulated']:.2f} %" if row["simulated"] else "-",
            f"{row['point_estimate']:.3e}",
            f"{row['simulated'] / row['measured']:.3f}",
            f"{row['image_ratio']:.3e}",
        ]
        if payload["draws"]:
            cells.insert(5, f"{row['band']['lo95']:.2e}-{row['band']['hi95']:.2e}")
        rows.append(cells)
    print(_table(headers, rows))
    print(
        "simulated = dPs/Pi through the detector aperture; image ratio = the paper's Eq. (2) "
        "over the signal rectangle"
    )
    print(f"time: {payload['seconds']:.2f} s (+{payload['compile_seconds']:.2f} s compile)")


def _command_predict(args: argparse.Namespace) -> None:
    from brdf_infer.params import resolve_params
    from brdf_infer.predict import predict_rows

    scene, measurements = _scene_and_measurements(args.scene, args.instrument)
    payload = predict_rows(scene, measurements, resolve_params(args.params))
    if args.json:
        _emit_json(payload)
        return
    print(f"instrument model '{payload['instrument']}' (README, \"Instrument models\")")
    headers = ["series", "sample", "theta_i [deg]", "theta_s [deg]", "measured", "predicted"]
    print(
        _table(
            [*headers, "pred/meas"],
            [
                [
                    row["series"],
                    row["sample"],
                    f"{row['theta_i_deg']:g}",
                    f"{row['theta_s_deg']:g}",
                    f"{row['measured']:.3e}",
                    f"{row['predicted']:.3e}",
                    f"{row['predicted'] / row['measured']:.3f}",
                ]
                for row in payload["rows"]
            ],
        )
    )


def _checked_instrument(name: str | None) -> None:
    """``--instrument``: a known instrument model (checked before the scene is read)."""
    from brdf_infer.instrument import INSTRUMENT_MODELS

    if name is not None and name not in INSTRUMENT_MODELS:
        raise BadInputError(
            f"unknown instrument model {name!r} (known: {', '.join(INSTRUMENT_MODELS)})",
            field="--instrument",
        )


def _instrument_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--instrument",
        help="what a raw reflectance is: point (Eq. 6), aperture (dPs/Pi through the detector "
        "aperture), image (Eq. 2 over the signal square) (default: the scene's [instrument])",
    )


def _command_sbc(args: argparse.Namespace) -> None:
    _headless()
    from brdf_infer.report import write_sbc
    from brdf_infer.sbc import COVERAGE_LEVELS, SbcSettings, check_planted_fault, run_sbc

    _checked_model(args.model)
    check_planted_fault(args.planted_fault, field="--planted-fault")
    scene, measurements = _scene_and_measurements(args.scene, args.instrument)
    check_planted_fault(args.planted_fault, scene, args.model, field="--planted-fault")
    settings = SbcSettings(
        replicates=args.replicates,
        draws=args.draws,
        thin=args.thin,
        warmup=args.warmup,
        seed=args.seed,
        sigma_scale=args.sigma_scale,
        target_accept=args.target_accept,
        warmup_tree_depth=args.warmup_tree_depth,
        planted_fault=args.planted_fault,
    )
    for name in ("replicates", "draws", "thin", "warmup"):
        if getattr(settings, name) < 1:
            raise BadInputError(
                f"must be at least 1, got {getattr(settings, name)}", field=f"--{name}"
            )
    if not settings.sigma_scale > 0:
        raise BadInputError(f"must be > 0, got {settings.sigma_scale}", field="--sigma-scale")
    if not 1 <= settings.warmup_tree_depth <= 10:
        raise BadInputError(
            f"must be 1 … 10, got {settings.warmup_tree_depth}", field="--warmup-tree-depth"
        )
    out = claim_output_dir(args.out or Path("reports") / scene.name / "sbc", "sbc", args.claims)
    _progress(
        f"simulation-based calibration of scene '{scene.name}': {settings.replicates} "
        f"replicates, truth ranked among {settings.draws} draws ..."
    )
    result = run_sbc(
        scene,
        measurements,
        settings,
        model=args.model,
        progress=not args.json and sys.stderr.isatty(),
    )
    write_sbc(out, result)
    if args.json:
        _emit_json({"out": str(out), **result.as_json()})
        return
    rows = [
        [
            name,
            f"{result.chi2_p[name]:.3f}",
            f"{result.ks_p[name]:.3f}",
            *(f"{100 * result.coverage[level][name]:.1f}" for level in COVERAGE_LEVELS),
        ]
        for name in result.quantities
    ]
    print(f"SBC of scene '{scene.name}': {settings.replicates} replicates, {settings.draws} draws")
    print(_table(["quantity", "chi2 p", "KS p", "50 % cov", "90 % cov", "95 % cov"], rows))
    verdict = "calibrated" if result.passed else "NOT calibrated: " + "; ".join(result.failures)
    print(f"verdict: {verdict}")
    print(
        f"time: {result.seconds:.0f} s ({result.compile_seconds:.0f} s compiling); "
        f"results in {out}/ (sbc.json, sbc.html)"
    )


def _command_batch(args: argparse.Namespace) -> None:
    _headless()
    from brdf_infer.batch import BatchInterrupted, BatchSettings, run_batch_until_signalled

    _checked_model(args.model)
    settings = BatchSettings(
        chains=args.chains,
        draws=args.draws,
        warmup=args.warmup,
        seed=args.seed,
        target_accept=args.target_accept,
        mode=args.mode,
        force=args.force,
    )
    settings.check()
    out = claim_output_dir(args.out or Path("reports") / "batch", "batch", args.claims)
    try:  # SIGINT and SIGTERM stop the batch, keeping the complete run folders
        result = run_batch_until_signalled(
            args.scenes, out, settings, model=args.model, progress=_progress, resume=args.resume
        )
    except BatchInterrupted as interrupted:
        # the complete run folders and batch.json are on disk, nothing half-written is left;
        # end now: the batch's threads may still run (they cannot be joined), and the
        # interpreter's teardown with JAX loaded alone takes seconds
        print(f"brdf-infer: {interrupted.message(out)}", file=sys.stderr, flush=True)
        sys.stdout.flush()
        os._exit(interrupted.exit_code)
    if args.json:
        _emit_json({"out": str(out), **result.as_json()})
        return
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
    print(_table(headers, rows))
    print(
        f"{len(result.entries)} scene(s) in {result.groups} compiled group(s) on "
        f"{result.devices} device(s): {result.seconds:.1f} s ({result.compile_seconds:.1f} s "
        f"compiling); summary in {out / 'batch.json'}"
    )


def _command_report(args: argparse.Namespace) -> None:
    _headless()
    from brdf_infer.report import write_report

    path, verdict = write_report(Path(args.run_dir), progress=_progress)
    if args.json:
        _emit_json({"report": str(path), "verdict": verdict.as_json()})
        return
    _print_verdict(verdict.as_json())
    print(f"report: {path}")


def _command_bench(args: argparse.Namespace) -> None:
    _headless()
    from brdf_infer.bench import write_report, write_speed_report, write_stress_report

    if args.stress:
        out = Path(args.out or "reports/benchmarks-stress.md")
        path = write_stress_report(out, args.quick, progress=_progress)
    elif args.speed:
        out = Path(args.out or "reports/benchmarks-speed.md")
        path = write_speed_report(out, args.quick, progress=_progress)
    else:
        path = write_report(Path(args.out or "reports/benchmarks.md"), args.quick, _progress)
    print(f"benchmark report written to {path}")


# --------------------------------------------------------------------------- parser


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows every option's default (a None or False default is left unsaid)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        if action.default is None or action.default is False or action.default == argparse.SUPPRESS:
            return action.help or ""
        return super()._get_help_string(action)


def build_parser() -> argparse.ArgumentParser:
    """The ``brdf-infer`` argument parser."""
    from brdf_infer.workflow import RunSettings

    parser = _Parser(
        prog="brdf-infer",
        description="Bayesian BRDF/TIS inference for black coatings (Strumik et al. 2024).",
        formatter_class=_HelpFormatter,
    )
    commands = parser.add_subparsers(
        dest="command", required=True, parser_class=_Parser, metavar="COMMAND"
    )

    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--no-cache",
        action="store_true",
        help="do not use the persistent compilation cache (BRDF_INFER_CACHE, else "
        "~/.cache/brdf_infer) for this run",
    )
    common.add_argument(
        "--device",
        choices=DEVICES,
        default="auto",
        help="where to compute: auto keeps single-scene work (run, posterior, fit, ...) on "
        "the CPU, where a small posterior is fastest, and gives batch, sbc, raytrace and "
        "bench the accelerator when JAX has one",
    )

    def command(name: str, help_text: str) -> argparse.ArgumentParser:
        return commands.add_parser(
            name,
            help=help_text,
            description=help_text,
            formatter_class=_HelpFormatter,
            parents=[common],
        )

    def scene_command(name: str, help_text: str) -> argparse.ArgumentParser:
        parser = command(name, help_text)
        parser.add_argument("scene", nargs="?", default="lya", help="built-in name or TOML path")
        parser.add_argument("--json", action="store_true", help="one JSON object on stdout")
        return parser

    run = scene_command(
        "run",
        "main job: paper fit, least squares, NUTS posterior and report in reports/<scene>/, "
        "plus the studies the scene's [studies] table or the options below ask for",
    )
    defaults = RunSettings()
    run.add_argument("--out", help="output directory (default: reports/<scene>)")
    run.add_argument("--example", help="also write the small committed example report here")
    run.add_argument("--chains", type=int, default=defaults.chains, help="NUTS chains")
    run.add_argument("--draws", type=int, default=defaults.draws, help="NUTS draws per chain")
    run.add_argument("--warmup", type=int, default=defaults.warmup, help="NUTS warmup per chain")
    run.add_argument("--seed", type=int, default=defaults.seed, help="random seed")
    studies = run.add_argument_group(
        "studies (default: the scene's [studies] table; any of these replaces it)"
    )
    studies.add_argument(
        "--full",
        action="store_true",
        help="every study the scene can run (other error model, instrument models, ray "
        "traces, model comparison, sensitivity to the error-model assumptions)",
    )
    studies.add_argument(
        "--error-models", nargs="+", metavar="NAME", help="posteriors under these error models"
    )
    studies.add_argument(
        "--instruments", nargs="+", metavar="NAME", help="posteriors under these instrument models"
    )
    studies.add_argument("--raytrace", action="store_true", help="ray-trace the posterior")
    studies.add_argument(
        "--compare", nargs="+", metavar="FAMILY", help="model families compared by PSIS-LOO"
    )
    studies.add_argument(
        "--sensitivity",
        action="store_true",
        help="posteriors with each error-model assumption changed (brdf-infer sensitivity)",
    )
    _model_argument(run)
    _instrument_argument(run)
    _force_argument(run)
    run.set_defaults(handler=_command_run)

    fit = scene_command(
        "fit", "fit Eq. (7): the paper's regression or least squares over all six parameters"
    )
    fit.add_argument("--method", choices=["paper", "lsq"], default="paper", help="fit method")
    _model_argument(fit)
    _instrument_argument(fit)
    fit.add_argument("--starts", type=int, default=16, help="lsq: number of starts")
    fit.add_argument(
        "--solver", choices=["lm", "gauss-newton", "dogleg"], default="lm", help="lsq: solver"
    )
    fit.add_argument("--seed", type=int, default=0, help="lsq: seed of the starting points")
    fit.add_argument(
        "--scale-covariance", action="store_true", help="lsq: scale covariance by reduced chi2"
    )
    fit.add_argument("--selection", help="data selection for --method paper (default: scene's)")
    fit.add_argument("--grid", action="store_true", help="grid search over (alpha, theta_s0)")
    _force_argument(fit)
    fit.set_defaults(handler=_command_fit)

    posterior = scene_command("posterior", "sample the posterior with NUTS or emcee")
    posterior.add_argument("--sampler", choices=["nuts", "emcee"], default="nuts", help="sampler")
    posterior.add_argument("--chains", type=int, default=4, help="NUTS chains")
    posterior.add_argument("--draws", type=int, default=1000, help="NUTS draws per chain")
    posterior.add_argument(
        "--warmup", type=int, help="NUTS warmup per chain (1000) or emcee burn-in steps (4000)"
    )
    posterior.add_argument(
        "--walkers", type=int, help="emcee walkers (default: max(24, 2 x dimension))"
    )
    posterior.add_argument("--steps", type=int, default=20000, help="emcee steps")
    posterior.add_argument("--seed", type=int, default=0, help="random seed")
    posterior.add_argument("--out", help="output directory (default: reports/<scene>/<sampler>)")
    posterior.add_argument(
        "--resume", action="store_true", help="continue an interrupted emcee run"
    )
    posterior.add_argument(
        "--error-model",
        choices=["generative", "spread"],
        help="override the scene's errors.model (spread: the earlier model, for comparison)",
    )
    posterior.add_argument(
        "--target-accept",
        type=float,
        default=0.8,
        help="NUTS target acceptance probability (raise towards 0.95 if a run diverges)",
    )
    _model_argument(posterior)
    _instrument_argument(posterior)
    _force_argument(posterior)
    posterior.set_defaults(handler=_command_posterior)

    batch = command("batch", "posteriors of many scenes, one compiled program per model structure")
    batch.add_argument("scenes", nargs="+", metavar="SCENE_OR_GLOB", help="scenes or globs")
    batch.add_argument(
        "--sampler", choices=["nuts"], default="nuts", help="sampler (NUTS: one compiled program)"
    )
    batch.add_argument("--chains", type=int, default=4, help="NUTS chains per scene")
    batch.add_argument("--draws", type=int, default=1000, help="NUTS draws per chain")
    batch.add_argument("--warmup", type=int, default=1000, help="NUTS warmup per chain")
    batch.add_argument("--seed", type=int, default=0, help="random seed (as posterior --seed)")
    batch.add_argument("--target-accept", type=float, default=0.8, help="NUTS target acceptance")
    batch.add_argument(
        "--mode",
        choices=["auto", "threads", "vmap"],
        default="auto",
        help="threads: one scene per CPU thread; vmap: one vmapped program, the scene axis "
        "sharded over every device (auto: threads on a single CPU, else vmap)",
    )
    batch.add_argument("--out", help="output directory (default: reports/batch)")
    batch.add_argument(
        "--resume",
        action="store_true",
        help="keep the scenes whose run folders in --out are complete (same scene, data and "
        "settings) and run the rest",
    )
    batch.add_argument("--json", action="store_true", help="one JSON object on stdout")
    _model_argument(batch)
    _force_argument(batch)
    batch.set_defaults(handler=_command_batch)

    tis = command("tis", "total integrated scatter, Eq. (9), of a parameter set or a run")
    source = tis.add_mutually_exclusive_group()
    source.add_argument("--params", help="parameter set name or JSON file (default: uv-paper)")
    source.add_argument("--run", help="posterior run directory: credible band over its draws")
    tis.add_argument(
        "--theta-i", type=float, nargs="+", default=[0, 5, 30, 50, 70], help="θi [deg]"
    )
    add_fold_arguments(tis, "a parameter set: no folding; a run: its scene's [model] fold")
    tis.add_argument("--json", action="store_true", help="one JSON object on stdout")
    tis.set_defaults(handler=_command_tis)

    brdf = command("brdf", "BRDF, in-plane Eq. (7) or hemisphere Eq. (8)")
    brdf.add_argument("--params", default="uv-paper", help="parameter set name or JSON file")
    brdf.add_argument("--theta-i", type=float, nargs="+", required=True, help="θi [deg]")
    brdf.add_argument(
        "--theta-s",
        type=float,
        nargs="+",
        required=True,
        help="in-plane theta_s (without --phi) or polar theta (with --phi) [deg]",
    )
    brdf.add_argument(
        "--phi", type=float, nargs="+", help="azimuth [deg] in [0, 360), forward plane at 180"
    )
    add_fold_arguments(brdf, "no folding")
    brdf.add_argument("--json", action="store_true", help="one JSON object on stdout")
    brdf.set_defaults(handler=_command_brdf)

    raytrace = scene_command(
        "raytrace", "ray-trace the series II setup (Sec. 6) and compare with the measurements"
    )
    trace_source = raytrace.add_mutually_exclusive_group()
    trace_source.add_argument(
        "--params", help="parameter set name or JSON file (default: the scene's reference set)"
    )
    trace_source.add_argument(
        "--run", help="posterior run directory: medians and 95 %% band over its draws"
    )
    raytrace.add_argument(
        "--rays", type=int, help="rays per configuration (and per draw with --run)"
    )
    raytrace.add_argument("--seed", type=int, default=0, help="random seed")
    raytrace.add_argument(
        "--estimator",
        choices=["nee", "naive"],
        default="nee",
        help="next-event estimation or the naive forward ray trace",
    )
    raytrace.add_argument("--draws", type=int, default=64, help="--run: draws in the band")
    raytrace.add_argument("--out", help="also write raytrace.json and figures here")
    raytrace.set_defaults(handler=_command_raytrace)

    predict = scene_command(
        "predict", "the model's prediction of every measurement row under an instrument model"
    )
    predict.add_argument(
        "--params",
        default="uv-paper",
        help="parameter set name, JSON file or inline JSON object of the six parameters",
    )
    _instrument_argument(predict)
    predict.set_defaults(handler=_command_predict)

    sbc = scene_command("sbc", "simulation-based calibration: is the scene's posterior calibrated?")
    sbc.add_argument("--replicates", type=int, default=200, help="simulated data sets")
    sbc.add_argument("--draws", type=int, default=100, help="posterior draws per replicate")
    sbc.add_argument("--thin", type=int, default=2, help="keep every THIN-th NUTS draw")
    sbc.add_argument("--warmup", type=int, default=300, help="NUTS warmup per replicate")
    sbc.add_argument("--seed", type=int, default=0, help="random seed")
    sbc.add_argument(
        "--sigma-scale",
        type=float,
        default=1.0,
        help="planted fault: scale the likelihood sigma by this in the inference only",
    )
    sbc.add_argument(
        "--planted-fault",
        help="planted fault in the inference only, which SBC must flag: jacobian (the "
        "whitening's log-Jacobian dropped) or prior (every free prior moved by one sd)",
    )
    sbc.add_argument("--target-accept", type=float, default=0.8, help="NUTS target acceptance")
    sbc.add_argument(
        "--warmup-tree-depth",
        type=int,
        default=6,
        help="largest NUTS tree depth during the warmup (10 after it)",
    )
    sbc.add_argument("--out", help="output directory (default: reports/<scene>/sbc)")
    _model_argument(sbc)
    _instrument_argument(sbc)
    sbc.set_defaults(handler=_command_sbc)

    export = scene_command(
        "export", "Zemax .BSDF tables or ABg fits of a parameter set or a posterior run"
    )
    add_export_arguments(export)
    export.set_defaults(handler=_command_export)

    compare = scene_command(
        "compare", "rank model families (Eq. 7, ABg, Harvey–Shack, Lambertian, …) by PSIS-LOO"
    )
    add_compare_arguments(compare)
    _force_argument(compare)
    _instrument_argument(compare)
    compare.set_defaults(handler=_command_compare)

    sensitivity = scene_command(
        "sensitivity",
        "the posterior under the scene's error model and with each assumption changed "
        "(calibration, rotation coupling, images per row, spread): TIS, π·BRDF0, PSIS-LOO",
    )
    add_sensitivity_arguments(sensitivity)
    sensitivity.set_defaults(handler=_command_sensitivity)

    design = command(
        "design",
        "where to measure next: the expected posterior sd of a target after new rows at each "
        "feasible setting, and the best K settings together",
    )
    add_design_arguments(design)
    design.set_defaults(handler=_command_design)

    report = command("report", "HTML report of a posterior run: the answer, then diagnostics")
    report.add_argument("run_dir", help="directory of a posterior run (posterior.nc, ...)")
    report.add_argument("--json", action="store_true", help="one JSON object on stdout")
    report.set_defaults(handler=_command_report)

    bench = command("bench", "error-against-run-time benchmarks of every numerical method")
    bench.add_argument("--quick", action="store_true", help="small sizes, a couple of minutes")
    bench.add_argument(
        "--out",
        help="Markdown report path (default: reports/benchmarks.md, with --speed "
        "reports/benchmarks-speed.md)",
    )
    bench.add_argument(
        "--speed",
        action="store_true",
        help="only the main job's speed: run and posterior cold and warm, the gradient, the "
        "peers on the same posterior",
    )
    bench.add_argument(
        "--stress",
        action="store_true",
        help="only the concurrency stress paths, 20 repetitions each under a watchdog "
        "(reports/benchmarks-stress.md)",
    )
    bench.set_defaults(handler=_command_bench)

    scenes = command("scenes", "list the built-in scenes")
    scenes.add_argument("--json", action="store_true", help="one JSON object on stdout")
    scenes.set_defaults(handler=_command_scenes)
    return parser


def _interrupt(signum, frame) -> NoReturn:
    raise KeyboardInterrupt


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code (2 for bad input)."""
    from brdf_infer._precision import Float32Error, require_float64

    args = build_parser().parse_args(argv)
    signal.signal(signal.SIGTERM, _interrupt)
    if getattr(args, "no_cache", False):  # before anything is compiled
        from brdf_infer._cache import disable_compilation_cache

        disable_compilation_cache()
    try:
        require_float64()
        # args.claims: the output folders the command holds (one writer per folder)
        with (
            contextlib.ExitStack() as args.claims,
            placement(args.command, getattr(args, "device", "auto")),
        ):
            args.handler(args)
    except (BadInputError, Float32Error) as error:
        print(f"brdf-infer: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as error:
        where = f"{error.filename}: " if error.filename else ""
        print(f"brdf-infer: error: {where}{error.strerror or error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        hint = " (continue it with --resume)" if getattr(args, "sampler", None) == "emcee" else ""
        print(f"brdf-infer: interrupted{hint}", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `brdf-infer ... | head`: the reader left, so do we
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    return 0


def entry_point() -> None:
    """Console-script entry point."""
    import brdf_infer  # noqa: F401  (switches JAX to float64 before any work)

    sys.exit(main())
