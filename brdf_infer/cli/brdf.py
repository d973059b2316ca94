"""``brdf-infer brdf``: the BRDF of a parameter set, in-plane (Eq. 7) or over the hemisphere
(Eq. 8)."""

from __future__ import annotations

import argparse

import numpy as np

from brdf_infer.cli._common import add_json_argument, command_parser, emit_json, table
from brdf_infer.cli._options import add_fold_arguments, angles, chosen_fold
from brdf_infer.errors import BadInputError


def add_parser(commands) -> argparse.ArgumentParser:
    """The options of ``brdf-infer brdf``."""
    parser = command_parser(commands, "brdf", "BRDF, in-plane Eq. (7) or hemisphere Eq. (8)")
    parser.add_argument("--params", default="uv-paper", help="parameter set name or JSON file")
    parser.add_argument("--theta-i", type=float, nargs="+", required=True, help="θi [deg]")
    parser.add_argument(
        "--theta-s",
        type=float,
        nargs="+",
        required=True,
        help="in-plane theta_s (without --phi) or polar theta (with --phi) [deg]",
    )
    parser.add_argument(
        "--phi", type=float, nargs="+", help="azimuth [deg] in [0, 360), forward plane at 180"
    )
    add_fold_arguments(parser, "no folding")
    add_json_argument(parser)
    parser.set_defaults(handler=main)
    return parser


def main(args: argparse.Namespace) -> int:
    """Print the BRDF at the given angles (broadcast against each other)."""
    from brdf_infer.model import brdf_hemisphere, brdf_inplane
    from brdf_infer.model.params import resolve_params

    params = resolve_params(args.params)
    arrays = _angle_arrays(args)
    in_plane = args.phi is None
    fold = chosen_fold(args.fold)
    if in_plane:
        values = brdf_inplane(arrays[0], arrays[1], params, fold=fold)
    else:
        values = brdf_hemisphere(arrays[0], arrays[1], arrays[2], params, fold=fold)
    payload = {
        "theta_i_deg": arrays[0].tolist(),
        "theta_s_deg": arrays[1].tolist(),
        "brdf": np.asarray(values).tolist(),
        "fold": fold,
    }
    if not in_plane:
        payload["phi_deg"] = arrays[2].tolist()
    if args.json:
        emit_json(payload)
        return 0
    headers = ["theta_i [deg]", "theta_s [deg]" if in_plane else "theta [deg]"]
    headers += [] if in_plane else ["phi [deg]"]
    rows = [
        [f"{v:g}" for v in column] + [f"{b:.4e}"]
        for *column, b in zip(*arrays, payload["brdf"], strict=True)
    ]
    print(table([*headers, "BRDF [sr^-1]"], rows))
    return 0


def _angle_arrays(args: argparse.Namespace) -> list[np.ndarray]:
    """θi, θs (and φ) checked and broadcast against each other."""
    theta_i = angles(args.theta_i, "--theta-i", 0.0, 90.0, upper_open=True)
    if args.phi is None:
        arrays = [theta_i, angles(args.theta_s, "--theta-s", -90.0, 90.0)]
    else:
        theta_s = angles(args.theta_s, "--theta-s", 0.0, 90.0)
        arrays = [theta_i, theta_s, angles(args.phi, "--phi", 0.0, 360.0, upper_open=True)]
    try:
        return np.broadcast_arrays(*arrays)
    except ValueError:
        raise BadInputError(
            "--theta-i, --theta-s and --phi need equal lengths (or length 1)", field="--theta-s"
        ) from None
