"""Access to the bundled data files (installed as the ``brdf_infer.data`` package)."""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path
from typing import Any


def data_path(name: str) -> Path:
    """Path of a bundled data file, e.g. ``data_path("lya_measurements.csv")``."""
    return Path(str(resources.files("brdf_infer.data").joinpath(name)))


def read_data_toml(name: str) -> dict[str, Any]:
    """Parse a bundled TOML file."""
    with data_path(name).open("rb") as handle:
        return tomllib.load(handle)
