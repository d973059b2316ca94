"""``brdf-infer scenes``: the built-in scenes."""

from __future__ import annotations

import argparse

from brdf_infer.cli._common import add_json_argument, command_parser, emit_json, table


def add_parser(commands) -> argparse.ArgumentParser:
    """The options of ``brdf-infer scenes``."""
    parser = command_parser(commands, "scenes", "list the built-in scenes")
    add_json_argument(parser)
    parser.set_defaults(handler=main)
    return parser


def main(args: argparse.Namespace) -> int:
    """List the built-in scenes with their descriptions."""
    from brdf_infer.scene import BUILTIN_SCENES, load_scene

    scenes = [load_scene(name) for name in BUILTIN_SCENES]
    entries = [{"name": s.name, "description": s.description, "path": str(s.path)} for s in scenes]
    if args.json:
        emit_json({"scenes": entries})
        return 0
    print(table(["scene", "description"], [[e["name"], e["description"]] for e in entries]))
    return 0
