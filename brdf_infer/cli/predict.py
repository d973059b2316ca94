"""``brdf-infer predict``: the model's prediction of every measurement row under an
instrument model (:func:`brdf_infer.predict.predict_rows`)."""

from __future__ import annotations

import argparse

from brdf_infer.cli._common import emit_json, scene_command_parser, table
from brdf_infer.cli._options import add_instrument_argument, scene_and_measurements


def add_parser(commands) -> argparse.ArgumentParser:
    """The options of ``brdf-infer predict``."""
    parser = scene_command_parser(
        commands,
        "predict",
        "the model's prediction of every measurement row under an instrument model",
    )
    parser.add_argument(
        "--params",
        default="uv-paper",
        help="parameter set name, JSON file or inline JSON object of the six parameters",
    )
    add_instrument_argument(parser)
    parser.set_defaults(handler=main)
    return parser


def main(args: argparse.Namespace) -> int:
    """Print each row's measured and predicted value."""
    from brdf_infer.model.params import resolve_params
    from brdf_infer.predict import predict_rows

    scene, measurements = scene_and_measurements(args.scene, args.instrument)
    payload = predict_rows(scene, measurements, resolve_params(args.params))
    if args.json:
        emit_json(payload)
        return 0
    print(f"instrument model '{payload['instrument']}' (README, \"Instrument models\")")
    headers = ["series", "sample", "theta_i [deg]", "theta_s [deg]", "measured", "predicted"]
    rows = [
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
    ]
    print(table([*headers, "pred/meas"], rows))
    return 0
