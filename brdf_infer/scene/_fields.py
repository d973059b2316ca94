"""Generic readers of a scene's TOML fields: each checks one value's type and range and
raises :class:`~brdf_infer.errors.BadInputError` naming the field."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from brdf_infer.errors import BadInputError


def _number(table: dict, key: str, path: Path, *, default: Any = None, positive=False) -> Any:
    value = table.get(key, default)
    if value is None:
        raise BadInputError("missing required key", file=path, field=key)
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise BadInputError(f"expected a number, got {value!r}", file=path, field=key)
    if positive and not value > 0:
        raise BadInputError(f"must be > 0, got {value!r}", file=path, field=key)
    return float(value)


def _table(document: dict, key: str, path: Path, allowed: set[str], parent: str = "") -> dict:
    label = parent + key
    table = document.get(key, {})
    if not isinstance(table, dict):
        raise BadInputError(f"expected a table [{label}]", file=path, field=label)
    for name in table:
        if name not in allowed:
            raise BadInputError(
                f"unknown key (allowed in [{label}]: {', '.join(sorted(allowed))})",
                file=path,
                field=f"{label}.{name}",
            )
    return table


def _boolean(table: dict, key: str, path: Path, prefix: str, default: bool) -> bool:
    value = table.get(key, default)
    if not isinstance(value, bool):
        raise BadInputError(f"expected true or false, got {value!r}", file=path, field=prefix + key)
    return value


def _count(table: dict, key: str, path: Path) -> int:
    """A positive integer key of the ``[bsdf]`` table (default 1)."""
    value = table.get(key, 1)
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise BadInputError(
            f"expected an integer >= 1, got {value!r}", file=path, field=f"bsdf.{key}"
        )
    return value


def _names(names, path: Path, field_name: str, known, what: str) -> tuple[str, ...]:
    if not isinstance(names, list) or not all(isinstance(name, str) for name in names):
        raise BadInputError(f"expected a list of {what} names", file=path, field=field_name)
    for name in names:
        if name not in known:
            raise BadInputError(
                f"unknown {what} {name!r} (known: {', '.join(known)})", file=path, field=field_name
            )
    return tuple(dict.fromkeys(names))


def _angle_range(table: dict, key: str, path: Path, default, low: float, high: float):
    value = table.get(key, list(default))
    if not (
        isinstance(value, list)
        and len(value) == 2
        and all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
        and low <= value[0] <= value[1] <= high
    ):
        raise BadInputError(
            f"expected [low, high] with {low:g} <= low <= high <= {high:g} deg, got {value!r}",
            file=path,
            field=f"design.{key}",
        )
    return (float(value[0]), float(value[1]))


def _string(document: dict, key: str, path: Path, default: str | None = None) -> str:
    value = document.get(key, default)
    if value is None:
        raise BadInputError("missing required key", file=path, field=key)
    if not isinstance(value, str):
        raise BadInputError(f"expected a string, got {value!r}", file=path, field=key)
    return value


def _pair(
    table: dict, key: str, path: Path, default: tuple[float, float], prefix: str = "raytrace."
) -> tuple[float, float]:
    value = table.get(key, list(default))
    if not (
        isinstance(value, list)
        and len(value) == 2
        and all(isinstance(v, int | float) and not isinstance(v, bool) and v > 0 for v in value)
    ):
        raise BadInputError(
            f"expected two positive numbers [mm], got {value!r}", file=path, field=prefix + key
        )
    return (float(value[0]), float(value[1]))


def _prefixed_number(
    table: dict, key: str, path: Path, default: float, prefix: str, *, positive: bool = True
) -> float:
    try:
        return _number(
            table, key, path, default=default, positive=positive and key != "image_theta_i_deg"
        )
    except BadInputError as error:
        raise BadInputError(error.problem, file=path, field=prefix + key) from None


def _choice(
    table: dict,
    key: str,
    path: Path,
    choices: tuple[str, ...],
    default: str,
    prefix: str = "errors.",
) -> str:
    value = table.get(key, default)
    if value not in choices:
        raise BadInputError(
            f"expected one of {', '.join(choices)}, got {value!r}", file=path, field=prefix + key
        )
    return value
