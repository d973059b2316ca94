"""Readers of the beam geometry (``[raytrace]``, ``[instrument]``) and the check that a
scene's instrument model has what it needs."""

from __future__ import annotations

from pathlib import Path

from brdf_infer.errors import BadInputError
from brdf_infer.scene._fields import _choice, _pair, _prefixed_number, _string, _table
from brdf_infer.scene._records import InstrumentSettings, RaytraceSettings, Scene


def _parse_raytrace(document: dict, path: Path, series: dict) -> RaytraceSettings | None:
    if "raytrace" not in document:
        return None
    defaults = RaytraceSettings()
    table = _table(document, "raytrace", path, set(RaytraceSettings.__dataclass_fields__))
    name = _string(table, "series", path, default=defaults.series)
    if name not in series:
        raise BadInputError(
            f"no [series.{name}] in this scene (known: {', '.join(series)})",
            file=path,
            field="raytrace.series",
        )
    return _setup(table, path, name, "raytrace.")


_GEOMETRY_KEYS = set(RaytraceSettings.__dataclass_fields__) - {
    "series",
    "rays",
    "image_theta_i_deg",
}


def _parse_instrument(document: dict, path: Path, scene_series: dict) -> InstrumentSettings:
    """The ``[instrument]`` table (schema: :class:`InstrumentSettings`)."""
    from brdf_infer.instrument import INSTRUMENT_MODELS, NODE_SHAPES

    defaults = InstrumentSettings()
    table = _table(document, "instrument", path, {"model", "nodes", "candidates", "series"})
    model = _choice(table, "model", path, INSTRUMENT_MODELS, defaults.model, "instrument.")
    nodes = table.get("nodes", defaults.nodes)
    if isinstance(nodes, bool) or not isinstance(nodes, int) or nodes not in NODE_SHAPES:
        raise BadInputError(
            f"expected one of {', '.join(map(str, NODE_SHAPES))}, got {nodes!r}",
            file=path,
            field="instrument.nodes",
        )
    candidates = table.get("candidates", defaults.candidates)
    if candidates is not None and (
        isinstance(candidates, bool) or not isinstance(candidates, int) or candidates < 256
    ):
        raise BadInputError(
            f"expected an integer >= 256, got {candidates!r}",
            file=path,
            field="instrument.candidates",
        )
    series_tables = _table(table, "series", path, set(scene_series), "instrument.")
    setups = {}
    for name in series_tables:
        prefix = f"instrument.series.{name}."
        geometry = _table(series_tables, name, path, _GEOMETRY_KEYS, "instrument.series.")
        setups[name] = _setup(geometry, path, name, prefix)
    return InstrumentSettings(model=model, nodes=nodes, candidates=candidates, series=setups)


def _setup(table: dict, path: Path, name: str, prefix: str) -> RaytraceSettings:
    """A beam geometry table (the ``[raytrace]`` keys) of series ``name``."""
    defaults = RaytraceSettings()
    apertures = table.get("beam_apertures_mm", [list(a) for a in defaults.beam_apertures_mm])
    if not (
        isinstance(apertures, list)
        and apertures
        and all(
            isinstance(a, list)
            and len(a) == 2
            and all(isinstance(v, int | float) and not isinstance(v, bool) and v > 0 for v in a)
            for a in apertures
        )
    ):
        raise BadInputError(
            "expected a list of [diameter, distance from the source] pairs, both > 0 [mm]",
            file=path,
            field=prefix + "beam_apertures_mm",
        )
    rays = table.get("rays", defaults.rays)
    if isinstance(rays, bool) or not isinstance(rays, int) or rays < 1:
        raise BadInputError(
            f"expected a positive integer, got {rays!r}", file=path, field=prefix + "rays"
        )
    settings = RaytraceSettings(
        series=name,
        beam_apertures_mm=tuple((float(d), float(z)) for d, z in apertures),
        sample_size_mm=_pair(table, "sample_size_mm", path, defaults.sample_size_mm, prefix),
        detector_size_mm=_pair(table, "detector_size_mm", path, defaults.detector_size_mm, prefix),
        signal_region_mm=_pair(table, "signal_region_mm", path, defaults.signal_region_mm, prefix),
        rays=rays,
        **{
            key: _prefixed_number(table, key, path, getattr(defaults, key), prefix)
            for key in (
                "source_diameter_mm",
                "source_distance_mm",
                "detector_behind_aperture_mm",
                "image_theta_i_deg",
            )
        },
    )
    if not 0 <= settings.image_theta_i_deg < 90:
        raise BadInputError(
            "expected an angle in [0, 90) deg", file=path, field=prefix + "image_theta_i_deg"
        )
    if max(z for _, z in settings.beam_apertures_mm) >= settings.source_distance_mm:
        raise BadInputError(
            "every beam aperture must lie between the source and the sample",
            file=path,
            field=prefix + "beam_apertures_mm",
        )
    return settings


def check_instrument(scene: Scene, model: str, field: str = "--instrument") -> Scene:
    """``scene`` predicting through instrument ``model``, checked: a kernel needs every
    raw-reflectance series' beam geometry and the out-of-plane BRDF (its nodes leave the
    plane of incidence).

    Raises:
        BadInputError: unknown model, a series without geometry, out_of_plane off.
    """
    from dataclasses import replace

    from brdf_infer.instrument import INSTRUMENT_MODELS

    if model not in INSTRUMENT_MODELS:
        raise BadInputError(
            f"unknown instrument model {model!r} (known: {', '.join(INSTRUMENT_MODELS)})",
            file=scene.path if field != "--instrument" else None,
            field=field,
        )
    if model != "point":
        where = {"file": scene.path, "field": field}
        missing = [
            name
            for name, geometry in scene.series.items()
            if geometry.quantity == "raw_reflectance" and scene.setup_of(name) is None
        ]
        if missing:
            raise BadInputError(
                f"instrument model {model!r} needs the beam geometry of series "
                f"{', '.join(missing)}: add [instrument.series.NAME] (the [raytrace] keys), "
                'or use model = "point"',
                **where,
            )
        if not scene.model.out_of_plane:
            raise BadInputError(
                f"instrument model {model!r} needs the out-of-plane BRDF of Eq. (8) "
                "(model.out_of_plane = true): its nodes leave the plane of incidence",
                **where,
            )
    return replace(scene, instrument=replace(scene.instrument, model=model))
