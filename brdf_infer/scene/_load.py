"""Finding and loading a scene file: a built-in name or a path."""

from __future__ import annotations

import tomllib
from pathlib import Path

from brdf_infer._internal.precision import ensure_float64
from brdf_infer._internal.resources import data_path
from brdf_infer.errors import BadInputError
from brdf_infer.scene._parse import parse_scene
from brdf_infer.scene._records import Scene

BUILTIN_SCENES: tuple[str, ...] = ("lya", "lya-fixed", "vis-532")
DEFAULT_SCENE = "lya"
_SCENE_SUFFIX = ".scene.toml"


def scene_file(name_or_path: str | Path) -> Path:
    """The TOML file of a built-in scene name or of a path."""
    text = str(name_or_path)
    if text in BUILTIN_SCENES:
        return data_path(text + _SCENE_SUFFIX)
    path = Path(text)
    if path.is_file():
        return path
    if path.exists():
        raise BadInputError("is not a file", file=path)
    raise BadInputError(
        f"neither a built-in scene ({', '.join(BUILTIN_SCENES)}) nor an existing TOML file",
        file=text,
    )


def load_scene(name_or_path: str | Path = DEFAULT_SCENE, *, check_files: bool = True) -> Scene:
    """Load and validate a scene by built-in name (``lya``) or TOML path.

    Every key is checked, and (``check_files``) every file the scene names is resolved and
    read, so that a bad scene fails before any work.

    Raises:
        BadInputError: unreadable file, TOML syntax error, unknown key, wrong type, a missing
            or malformed measurement or reference file.
    """
    ensure_float64()
    path = scene_file(name_or_path)
    try:
        with path.open("rb") as handle:
            document = tomllib.load(handle)
    except tomllib.TOMLDecodeError as error:
        raise BadInputError(f"invalid TOML: {error}", file=path) from None
    except (OSError, UnicodeDecodeError) as error:
        raise BadInputError(f"cannot read: {error}", file=path) from None
    scene = parse_scene(document, path)
    if check_files:
        scene.check_files()
    return scene
