"""Scenes: a TOML file naming the measurements, the geometry of each series, the error model
and the analysis settings (README, "Your own data"). Built-in scenes ship in ``data/``.

Schema (keys other than these are errors; defaults in brackets)::

    name = "my-coating"                      # required
    description = "..."                      # [""]
    wavelength_nm = 121.6                    # [unset]
    measurements = "my_measurements.csv"     # required, relative to the scene file
    [series.NAME]                            # one table per series named in the CSV
    aperture_diameter_mm = 7.2               # required, > 0
    aperture_distance_mm = 103.8             # required, > 0
    [errors]                                 # brdf_infer.error_model explains the model
    model = "generative"                     # ["generative"] or "spread" (the earlier model)
    calibration = "per_series"               # ["per_series"], "per_sample" or "none": rows
                                             #   sharing one reference's calibration factor
    calibration_rel = 0.065                  # [0.065] relative 1σ of a calibration factor
    rotation_coupling = "camera_follows"     # ["camera_follows"] θs + ε under a sample
                                             #   rotation ε, or "camera_fixed" (θs − ε)
    images_per_row = 12                      # [1] images averaged into each row's value; or
                                             #   per series: { I = 12 } (series not named: 1)
    reflectance_rel = 0.065                  # [0.065] relative 1σ of one image of a row
                                             #   without reflectance_err (and spread's σ_rel)
    angle_deg = 1.0                          # [1.0] 1σ of the angles [deg]
    rotation_deg = 1.0                       # [angle_deg] sample rotation per (series,
                                             #   sample, θi) setting [deg]
    camera_deg = 1.0                         # [angle_deg] camera position per row [deg]
    propagate_angles = true                  # [true] angle errors through ln R
    angle_method = "linearised"              # ["linearised"] or "latent" (errors in variables)
    hierarchical = true                      # [true] per-sample random effect, learned scale
    sample_sd_prior = 0.2                    # [0.2] half-normal scale of its prior [ln R]
    repeatability = "learned"                # ["learned"] or a fixed per-row 1σ [ln R]
    repeatability_sd_prior = 0.1             # [0.1] half-normal scale of its prior [ln R]
    [model]
    fold = false                             # [false] Eq. (10), a measurement artefact, in
                                             #   the likelihood and the run's products (bands,
                                             #   TIS, maps, exports); false: physical BRDF
    out_of_plane = true                      # [true] Eq. (8): hemisphere products (TIS, maps)
    c1 = -0.95                               # [paper] Eq. (8) Δφ slope
    c2_deg = 90.5                            # [paper] Eq. (8) Δφ offset [deg]
    fold_a_per_deg = 0.35                    # [paper] Eq. (10) a [deg⁻¹]
    fold_theta_sf_deg = 87.0                 # [paper] Eq. (10) θsf [deg]
    [paper_fit]
    alpha = 4.5                              # [4.5] fixed α of the linear regression
    theta_s0_deg = -12.0                     # [-12.0] fixed θs0 [deg]
    selection = "paper"                      # ["paper"] see brdf_infer.selections.SELECTIONS
    [outputs]
    theta_i_deg = [18, 45, 60, 75, 80]       # [the measured θi, at most 6] BRDF bands [deg]
    tis = true                               # [true] TIS band (needs out_of_plane)
    maps = true                              # [true] hemisphere maps (needs out_of_plane)
    tis_reference = "reference.csv"          # [none] theta_i_deg,tis,label points to compare
    reference_params = "uv-paper"            # [none] parameter set drawn beside the bands
    [priors.NAME]                            # NAME in brdf0, a1, a2, a3, alpha, theta_s0
    kind = "normal"                          # [brdf_infer.priors.DEFAULT_PRIORS] see priors.py
    loc = 0.0
    scale = 10.0
    [raytrace]                               # [absent: no ray tracing] setup of Sec. 6 [mm]
    series = "II"                            # ["II"] series simulated; its AD d and r are used
    source_diameter_mm = 0.5                 # [0.5] source disk
    source_distance_mm = 360.0               # [360] source – sample centre
    beam_apertures_mm = [[4.8, 32.0], [16.0, 93.0], [4.63, 211.0]]  # [these] [diameter,
                                             #   distance from the source] of A1, A2, A3
    sample_size_mm = [40.0, 40.0]            # [40 × 40] in-plane × across
    detector_size_mm = [25.6, 6.375]         # [25.6 × 6.375] detector plane, in-plane × across
    detector_behind_aperture_mm = 30.0       # [30] detector plane behind AD
    signal_region_mm = [2.6, 2.6]            # [2.6 × 2.6] centred rectangle of the image ratio
                                             #   (100 × 100 pixels of 26 µm, Sec. 3.1)
    rays = 1000000                           # [1e6] rays per configuration
    image_theta_i_deg = 80.0                 # [80] θi of the simulated images (Fig. 13)
    [instrument]                             # what the likelihood predicts (brdf_infer.instrument)
    model = "point"                          # ["point"] Eq. (6); "aperture": dPs/Pi through AD;
                                             #   "image": Eq. (2) over the signal rectangle
    nodes = 16                               # [16] kernel nodes per row: 8, 16, 32, 64, 128
    candidates = 65536                       # [2^16 aperture, 2^18 image] Sobol points
                                             #   compressed into them
    [instrument.series.NAME]                 # [the [raytrace] table for its series] beam
                                             #   geometry of series NAME: the [raytrace] keys
                                             #   source_diameter_mm … signal_region_mm
    [studies]                                # what `run` adds to the one posterior [none]
    error_models = ["spread"]                # [] posteriors under other error models
    sensitivity = true                       # [false] posteriors under each error-model
                                             #   assumption changed (brdf_infer.sensitivity)
    instruments = ["aperture", "image"]      # [] posteriors under other instrument models
    raytrace = true                          # [false] ray-trace the posterior ([raytrace])
    compare = ["strumik2024", "abg"]         # [] model families compared by PSIS-LOO
    design = "tis:70"                        # [unset] where to measure next for this target
                                             #   (brdf_infer.design; tis:THETA, pi_brdf0, ...)
    [design]                                 # the settings a new row may take (brdf-infer design)
    theta_i_deg = [10.0, 85.0]               # [[10, 85]] θi range [deg]
    theta_s_deg = [-85.0, 85.0]              # [[-85, 85]] signed in-plane θs range [deg]
    step_deg = 5.0                           # [5] grid step [deg]
    source_clearance_deg = 10.0              # [10] least lab angle |θi + θs| between the
                                             #   camera and the incident beam [deg]
    series = "II"                            # [the series with the most rows] the series
                                             #   (aperture, calibration) a new row joins
    budget = 3                               # [3] rows chosen together
"""

from __future__ import annotations

import csv
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from brdf_infer._resources import data_path
from brdf_infer.bsdf_measurements import BSDF_SERIES, is_bsdf_path, measurements_from_bsdf
from brdf_infer.error_model import (
    ANGLE_METHODS,
    CALIBRATIONS,
    ERROR_MODELS,
    LEARNED,
    ROTATION_COUPLINGS,
    ErrorSettings,
)
from brdf_infer.errors import BadInputError
from brdf_infer.measurements import QUANTITIES, Measurements, load_measurements
from brdf_infer.params import PAPER_CONSTANTS, PARAM_NAMES, PARAMETER_SETS, HemisphereConstants
from brdf_infer.priors import DEFAULT_PRIORS, Prior, parse_prior
from brdf_infer.selections import SELECTIONS

BUILTIN_SCENES: tuple[str, ...] = ("lya", "lya-fixed", "vis-532")
MAX_DEFAULT_BAND_ANGLES = 6
DEFAULT_SCENE = "lya"
_SCENE_SUFFIX = ".scene.toml"


@dataclass(frozen=True)
class SeriesGeometry:
    """What one measurement series measured, and its detector aperture (Eq. 6).

    Attributes:
        aperture_diameter_mm: diameter d [mm] (None for a ``brdf`` series).
        aperture_distance_mm: aperture–sample distance r [mm] (None for a ``brdf`` series).
        quantity: ``raw_reflectance`` (through the aperture, Eq. 2) or ``brdf`` [sr⁻¹].
    """

    aperture_diameter_mm: float | None
    aperture_distance_mm: float | None
    quantity: str = "raw_reflectance"


@dataclass(frozen=True)
class ModelSettings:
    """Which model components the scene uses, and the constants of Eqs. (8), (10).

    Attributes:
        fold: the one fold switch: the folding term of Eq. (10) in the likelihood's
            predictions and in the run's products (BRDF and TIS bands, hemisphere maps,
            exports). False (the default): the physical BRDF, conservative for stray light.
        out_of_plane: the full-hemisphere extension of Eq. (8) is on; without it no
            hemisphere product (TIS, maps) is built.
        constants: out-of-plane and folding constants.
        family: the BRDF family that ``fit``, ``posterior``, ``run`` and ``sbc`` use unless
            ``--model`` names another (``strumik2024``: Eqs. 7, 8, 10, the default).
    """

    fold: bool = False
    out_of_plane: bool = True
    constants: HemisphereConstants = PAPER_CONSTANTS
    family: str = "strumik2024"


@dataclass(frozen=True)
class OutputSettings:
    """Which products a run makes.

    Attributes:
        theta_i_deg: incidence angles of the in-plane BRDF bands [deg] (None: the measured
            ones, see :meth:`Scene.band_theta_i_deg`).
        tis: make the TIS band (only with the out-of-plane extension).
        maps: make the hemisphere maps (only with the out-of-plane extension).
        tis_reference: CSV of reference TIS points (theta_i_deg, tis, label), or None.
        reference_params: a named parameter set drawn beside the BRDF bands, or None.
    """

    theta_i_deg: tuple[float, ...] | None = None
    tis: bool = True
    maps: bool = True
    tis_reference: Path | None = None
    reference_params: str | None = None


@dataclass(frozen=True)
class PaperFitSettings:
    """The paper's linear regression (Sec. 4.2).

    Attributes:
        alpha: fixed exponent α [-].
        theta_s0_deg: fixed θs0 [deg].
        selection: name of the data selection (``brdf_infer.selections.SELECTIONS``).
    """

    alpha: float = 4.5
    theta_s0_deg: float = -12.0
    selection: str = "paper"


@dataclass(frozen=True)
class RaytraceSettings:
    """The measurement setup of Sec. 6 (Fig. 12) for the ray-tracing validation [mm].

    The detector aperture AD (diameter and distance from the sample) is the scene's geometry
    of ``series``.

    Attributes:
        series: the measurement series simulated.
        source_diameter_mm: diameter of the source disk.
        source_distance_mm: source – sample-centre distance.
        beam_apertures_mm: (diameter, distance from the source) of each beam aperture.
        sample_size_mm: sample side lengths (in the plane of incidence, across).
        detector_size_mm: detector plane (in the plane of incidence, across).
        detector_behind_aperture_mm: detector plane distance behind AD.
        signal_region_mm: centred rectangle of the image ratio (Eq. 2 applied to images).
        rays: default number of rays per configuration.
        image_theta_i_deg: incidence angle of the simulated detector images (Fig. 13) [deg].
    """

    series: str = "II"
    source_diameter_mm: float = 0.5
    source_distance_mm: float = 360.0
    beam_apertures_mm: tuple[tuple[float, float], ...] = ((4.8, 32.0), (16.0, 93.0), (4.63, 211.0))
    sample_size_mm: tuple[float, float] = (40.0, 40.0)
    detector_size_mm: tuple[float, float] = (25.6, 6.375)
    detector_behind_aperture_mm: float = 30.0
    signal_region_mm: tuple[float, float] = (2.6, 2.6)
    rays: int = 1_000_000
    image_theta_i_deg: float = 80.0


@dataclass(frozen=True)
class InstrumentSettings:
    """What the likelihood predicts for a raw-reflectance row (:mod:`brdf_infer.instrument`).

    Attributes:
        model: ``point`` (Eq. 6, the article's), ``aperture`` (dPs/Pi through AD averaged
            over beam footprint and aperture) or ``image`` (Eq. 2 over the signal rectangle).
        nodes: kernel nodes per row.
        candidates: Sobol points of the full cubature, compressed into ``nodes`` (None:
            the instrument's default, ``brdf_infer.instrument.DEFAULT_CANDIDATES``).
        series: beam geometry of each series named in ``[instrument.series.NAME]``.
    """

    model: str = "point"
    nodes: int = 16
    candidates: int | None = None
    series: dict[str, RaytraceSettings] = field(default_factory=dict)


@dataclass(frozen=True)
class Studies:
    """What ``run`` does beyond the scene's one posterior (``[studies]``; each off by default).

    Attributes:
        error_models: further posteriors under these error models (``spread``), beside the
            scene's, compared by PSIS-LOO in the report.
        instruments: further posteriors under these instrument models (``aperture``,
            ``image``), side by side with the scene's, each ray-traced where it can be.
        raytrace: ray-trace the posterior (and ``[outputs] reference_params``) through the
            ``[raytrace]`` setup (Sec. 6).
        compare: model families compared by PSIS-LOO (at least two).
        sensitivity: posteriors with each error-model assumption changed
            (:mod:`brdf_infer.sensitivity`).
    """

    error_models: tuple[str, ...] = ()
    instruments: tuple[str, ...] = ()
    raytrace: bool = False
    compare: tuple[str, ...] = ()
    sensitivity: bool = False
    design: str | None = None

    def requested(self) -> list[str]:
        """One phrase per study asked for."""
        asked = [f"error model {name}" for name in self.error_models]
        asked += [f"instrument model {name}" for name in self.instruments]
        asked += ["ray traces"] * self.raytrace
        asked += [f"comparison of {', '.join(self.compare)}"] if self.compare else []
        asked += ["sensitivity to the error-model assumptions"] * self.sensitivity
        asked += [f"where to measure next ({self.design})"] if self.design else []
        return asked


@dataclass(frozen=True)
class DesignSettings:
    """The ``[design]`` table: the settings a new row may take (:mod:`brdf_infer.design`).

    Attributes:
        theta_i_deg: (low, high) incidence angles [deg].
        theta_s_deg: (low, high) signed in-plane scattering angles [deg] (> 0: forward side).
        step_deg: grid step in θi and θs [deg].
        source_clearance_deg: the least lab angle |θi + θs| between the camera and the
            incident beam [deg]; the camera cannot stand in the beam (θs = −θi is the
            retro-reflection direction, the source itself).
        series: the series whose aperture and calibration a new row shares (None: the series
            with the most rows).
        budget: rows chosen together by default.
    """

    theta_i_deg: tuple[float, float] = (10.0, 85.0)
    theta_s_deg: tuple[float, float] = (-85.0, 85.0)
    step_deg: float = 5.0
    source_clearance_deg: float = 10.0
    series: str | None = None
    budget: int = 3  # as brdf_infer.settings.DesignOptions (a test holds them equal)


@dataclass(frozen=True)
class Scene:
    """A validated scene."""

    name: str
    path: Path
    measurements_path: Path
    series: dict[str, SeriesGeometry]
    description: str = ""
    wavelength_nm: float | None = None
    errors: ErrorSettings = field(default_factory=ErrorSettings)
    model: ModelSettings = field(default_factory=ModelSettings)
    paper_fit: PaperFitSettings = field(default_factory=PaperFitSettings)
    outputs: OutputSettings = field(default_factory=OutputSettings)
    priors: dict[str, Prior] = field(default_factory=lambda: dict(DEFAULT_PRIORS))
    raytrace: RaytraceSettings | None = None
    studies: Studies = field(default_factory=Studies)
    bsdf_thinning: tuple[int, int] = (1, 1)
    instrument: InstrumentSettings = field(default_factory=InstrumentSettings)
    design: DesignSettings = field(default_factory=DesignSettings)

    def setup_of(self, series: str) -> RaytraceSettings | None:
        """The beam geometry of a series: ``[instrument.series.NAME]``, else the
        ``[raytrace]`` table when it simulates that series, else None."""
        if series in self.instrument.series:
            return self.instrument.series[series]
        if self.raytrace is not None and self.raytrace.series == series:
            return self.raytrace
        return None

    @property
    def free_parameters(self) -> tuple[str, ...]:
        """Names of the parameters that are not fixed, in ``Params`` order."""
        return tuple(name for name in PARAM_NAMES if not self.priors[name].fixed)

    def band_theta_i_deg(self, measurements: Measurements) -> tuple[float, ...]:
        """Incidence angles of the in-plane BRDF bands [deg]: the scene's ``[outputs]
        theta_i_deg``, else the measured ones (at most six, spread over their range)."""
        if self.outputs.theta_i_deg is not None:
            return self.outputs.theta_i_deg
        angles = np.unique(measurements.theta_i_deg)
        if angles.size > MAX_DEFAULT_BAND_ANGLES:
            picks = np.round(np.linspace(0, angles.size - 1, MAX_DEFAULT_BAND_ANGLES)).astype(int)
            angles = angles[picks]
        return tuple(float(a) for a in angles)

    @property
    def makes_tis(self) -> bool:
        return self.model.out_of_plane and self.outputs.tis

    @property
    def makes_maps(self) -> bool:
        return self.model.out_of_plane and self.outputs.maps

    def load_tis_reference(self) -> list[tuple[float, float, str]]:
        """Reference TIS points (θi [deg], TIS [-], label) of the scene, possibly none."""
        if self.outputs.tis_reference is None:
            return []
        path = self.outputs.tis_reference
        try:
            with path.open(encoding="utf-8-sig") as handle:
                rows = list(csv.DictReader(handle))
            points = [(float(r["theta_i_deg"]), float(r["tis"]), r["label"]) for r in rows]
        except (OSError, KeyError, ValueError, TypeError, UnicodeDecodeError) as error:
            raise BadInputError(
                f"cannot read theta_i_deg,tis,label: {error}",
                file=path,
                field="outputs.tis_reference",
            ) from None
        if not points:
            raise BadInputError(
                "no rows after the header theta_i_deg,tis,label",
                file=path,
                field="outputs.tis_reference",
            )
        return points

    def load_measurements(self) -> Measurements:
        """The scene's measurement table, validated against its series (a .BSDF table: its
        BRDF values, thinned as ``[bsdf]`` says)."""
        if is_bsdf_path(self.measurements_path):
            return measurements_from_bsdf(self.measurements_path, *self.bsdf_thinning)
        return load_measurements(
            self.measurements_path,
            known_series=self.series,
            series_quantity={name: g.quantity for name, g in self.series.items()},
        )

    def check_files(self) -> None:
        """Resolve and read every file the scene names, before any work.

        Raises:
            BadInputError: a file is missing or malformed; the message names the scene, the
                key and the resolved path.
        """
        for key, path in (
            ("measurements", self.measurements_path),
            ("outputs.tis_reference", self.outputs.tis_reference),
        ):
            if path is None:
                continue
            try:
                if path.is_file():
                    continue
                what = "is not a file" if path.exists() else "no such file"
                where = path.resolve()
            except (OSError, ValueError) as error:  # a name too long, a NUL in it
                what, where = f"cannot read ({getattr(error, 'strerror', None) or error})", path
            raise BadInputError(
                f"{what}: {where} (named by scene '{self.name}')", file=self.path, field=key
            )
        self.load_measurements()
        self.load_tis_reference()

    def apertures(self, measurements: Measurements) -> tuple[np.ndarray, np.ndarray]:
        """Aperture diameter d and distance r [mm] of each measurement row's series (NaN for
        the rows of a ``brdf`` series)."""
        d = [self.series[s].aperture_diameter_mm for s in measurements.series]
        r = [self.series[s].aperture_distance_mm for s in measurements.series]
        return (
            np.array([np.nan if v is None else v for v in d]),
            np.array([np.nan if v is None else v for v in r]),
        )

    def log_conversion(self, measurements: Measurements) -> np.ndarray:
        """ln(measured value / BRDF) of each row: ln(Ω cos θs) of Eq. (6) for raw reflectance
        through an aperture, 0 for BRDF rows."""
        from brdf_infer.model import log_aperture_factor

        d, r = self.apertures(measurements)
        brdf_rows = ~np.isfinite(d)
        safe_d, safe_r = np.where(brdf_rows, 1.0, d), np.where(brdf_rows, 1.0, r)
        factor = np.asarray(log_aperture_factor(measurements.theta_s_deg, safe_d, safe_r))
        return np.where(brdf_rows, 0.0, factor)

    def measured_log_brdf(self, measurements: Measurements) -> np.ndarray:
        """ln BRDF of each row: the measured value converted through Eq. (6) where needed."""
        return np.log(measurements.reflectance) - self.log_conversion(measurements)


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


def _model_family(model: dict, path: Path) -> str:
    """``[model] family``, one of the model families (default ``strumik2024``)."""
    from brdf_infer.model import check_family_name

    name = model.get("family", "strumik2024")
    check_family_name(name, file=path, field="model.family")
    return name


def _count(table: dict, key: str, path: Path) -> int:
    """A positive integer key of the ``[bsdf]`` table (default 1)."""
    value = table.get(key, 1)
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise BadInputError(
            f"expected an integer >= 1, got {value!r}", file=path, field=f"bsdf.{key}"
        )
    return value


def _compare_families(names, path: Path, field_name: str) -> tuple[str, ...]:
    """Model families to compare by PSIS-LOO (at least two; none: no comparison)."""
    from brdf_infer.model import FAMILY_NAMES

    names = _names(names, path, field_name, FAMILY_NAMES, "model family")
    if len(names) == 1:
        raise BadInputError("name at least two families to compare", file=path, field=field_name)
    return names


def _names(names, path: Path, field_name: str, known, what: str) -> tuple[str, ...]:
    if not isinstance(names, list) or not all(isinstance(name, str) for name in names):
        raise BadInputError(f"expected a list of {what} names", file=path, field=field_name)
    for name in names:
        if name not in known:
            raise BadInputError(
                f"unknown {what} {name!r} (known: {', '.join(known)})", file=path, field=field_name
            )
    return tuple(dict.fromkeys(names))


def _parse_studies(document: dict, path: Path) -> Studies:
    """The ``[studies]`` table (and the older top-level ``compare = [...]``)."""
    from brdf_infer.error_model import ERROR_MODELS
    from brdf_infer.instrument import INSTRUMENT_MODELS

    table = _table(document, "studies", path, set(Studies.__dataclass_fields__))
    if "compare" in document and "compare" in table:
        raise BadInputError(
            "give compare once: in [studies] (the top-level key is its older form)",
            file=path,
            field="studies.compare",
        )
    compare = table.get("compare", document.get("compare", []))
    field_name = "studies.compare" if "compare" in table else "compare"
    return Studies(
        error_models=_names(
            table.get("error_models", []),
            path,
            "studies.error_models",
            ERROR_MODELS,
            "error model",
        ),
        instruments=_names(
            table.get("instruments", []),
            path,
            "studies.instruments",
            INSTRUMENT_MODELS,
            "instrument model",
        ),
        raytrace=_boolean(table, "raytrace", path, "studies.", False),
        compare=_compare_families(compare, path, field_name),
        sensitivity=_boolean(table, "sensitivity", path, "studies.", False),
        design=_design_target(table, path),
    )


def _design_target(table: dict, path: Path) -> str | None:
    from brdf_infer._design_target import parse_target

    if "design" not in table:
        return None
    parse_target(table["design"], field="studies.design", file=path)
    return table["design"].strip()


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


def _parse_design(document: dict, path: Path, series: dict) -> DesignSettings:
    """The ``[design]`` table (:class:`DesignSettings`)."""
    table = _table(document, "design", path, set(DesignSettings.__dataclass_fields__))
    defaults = DesignSettings()
    name = table.get("series")
    if name is not None and name not in series:
        raise BadInputError(
            f"no series {name!r} in the scene (known: {', '.join(series)})",
            file=path,
            field="design.series",
        )
    clearance = _number(table, "source_clearance_deg", path, default=defaults.source_clearance_deg)
    if not 0.0 <= clearance < 90.0:
        raise BadInputError(
            f"expected an angle in [0, 90) deg, got {clearance:g}",
            file=path,
            field="design.source_clearance_deg",
        )
    try:
        step = _number(table, "step_deg", path, default=defaults.step_deg, positive=True)
    except BadInputError as error:
        raise BadInputError(error.problem, file=path, field="design.step_deg") from None
    budget = table.get("budget", defaults.budget)
    if isinstance(budget, bool) or not isinstance(budget, int) or not 1 <= budget <= 10:
        raise BadInputError(
            f"expected an integer in [1, 10], got {budget!r}", file=path, field="design.budget"
        )
    return DesignSettings(
        theta_i_deg=_angle_range(table, "theta_i_deg", path, defaults.theta_i_deg, 0.0, 89.0),
        theta_s_deg=_angle_range(table, "theta_s_deg", path, defaults.theta_s_deg, -89.0, 89.0),
        step_deg=step,
        source_clearance_deg=clearance,
        series=name,
        budget=budget,
    )


def _scene_name(document: dict, path: Path) -> str:
    """``name``: it names the scene's results folder (``reports/<name>``, a batch's
    ``OUT/<name>``), so it is a plain folder name."""
    name = _string(document, "name", path)
    if not name.strip() or name in (".", "..") or any(c in name for c in "/\\\x00"):
        raise BadInputError(
            f"expected a non-empty name without '/', got {name!r} (it names the results folder)",
            file=path,
            field="name",
        )
    return name


def _selection(paper: dict, path: Path) -> str:
    """``[paper_fit] selection``: a name of :data:`brdf_infer.selections.SELECTIONS`."""
    name = _string(paper, "selection", path, default="paper")
    if name not in SELECTIONS:
        raise BadInputError(
            f"unknown selection {name!r} (known: {', '.join(SELECTIONS)})",
            file=path,
            field="paper_fit.selection",
        )
    return name


def _string(document: dict, key: str, path: Path, default: str | None = None) -> str:
    value = document.get(key, default)
    if value is None:
        raise BadInputError("missing required key", file=path, field=key)
    if not isinstance(value, str):
        raise BadInputError(f"expected a string, got {value!r}", file=path, field=key)
    return value


_TOP_KEYS = {
    "instrument",
    "name",
    "description",
    "wavelength_nm",
    "measurements",
    "series",
    "errors",
    "model",
    "paper_fit",
    "outputs",
    "priors",
    "raytrace",
    "compare",
    "studies",
    "bsdf",
    "design",
}


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


_REPLACED_ERROR_KEYS = {
    "reflectance_rel_kind": 'replaced by errors.calibration = "per_series" | "per_sample" | '
    '"none" and errors.calibration_rel (the old "calibration" kind is calibration = '
    '"per_series" with calibration_rel = the old reflectance_rel; "per_row" is calibration = '
    '"none"; README, "Error model")',
}


def _images_per_row(table: dict, path: Path, series: tuple[str, ...]) -> int | dict[str, int]:
    """``errors.images_per_row``: a positive integer, or a table series name → integer."""

    def count(value, field: str) -> int:
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise BadInputError(
                f"expected a positive integer, got {value!r}", file=path, field=field
            )
        return value

    value = table.get("images_per_row", ErrorSettings().images_per_row)
    if not isinstance(value, dict):
        return count(value, "errors.images_per_row")
    for name in value:
        if name not in series:
            raise BadInputError(
                f"no series {name!r} in the scene (series: {', '.join(series)})",
                file=path,
                field=f"errors.images_per_row.{name}",
            )
    return {name: count(n, f"errors.images_per_row.{name}") for name, n in value.items()}


def parse_errors(table: dict, path: Path, series: tuple[str, ...]) -> ErrorSettings:
    """The ``[errors]`` table (schema: :class:`brdf_infer.error_model.ErrorSettings`) of a
    scene with these ``series``.

    Raises:
        BadInputError: an unknown or replaced key, or a value out of range (naming the field).
    """
    defaults = ErrorSettings()
    for key, replacement in _REPLACED_ERROR_KEYS.items():
        if key in table:
            raise BadInputError(replacement, file=path, field="errors." + key)
    table = _table({"errors": table}, "errors", path, set(ErrorSettings.__dataclass_fields__))

    def number(key: str, default: float, *, positive: bool = False) -> float:
        value = _prefixed_number(table, key, path, default, "errors.", positive=False)
        if value < 0 or (positive and value == 0):
            bound = "> 0" if positive else ">= 0"
            raise BadInputError(f"must be {bound}, got {value:g}", file=path, field="errors." + key)
        return value

    repeatability = table.get("repeatability", defaults.repeatability)
    if isinstance(repeatability, str) and repeatability != LEARNED:
        raise BadInputError(
            f'expected "{LEARNED}" or a number >= 0, got {repeatability!r}',
            file=path,
            field="errors.repeatability",
        )
    if repeatability != LEARNED:
        repeatability = number("repeatability", 0.0)
    angle = number("angle_deg", defaults.angle_deg)
    return ErrorSettings(
        model=_choice(table, "model", path, ERROR_MODELS, defaults.model),
        reflectance_rel=number("reflectance_rel", defaults.reflectance_rel),
        calibration=_choice(table, "calibration", path, CALIBRATIONS, defaults.calibration),
        calibration_rel=number("calibration_rel", defaults.calibration_rel),
        rotation_coupling=_choice(
            table, "rotation_coupling", path, ROTATION_COUPLINGS, defaults.rotation_coupling
        ),
        images_per_row=_images_per_row(table, path, series),
        angle_deg=angle,
        rotation_deg=number("rotation_deg", angle),
        camera_deg=number("camera_deg", angle),
        propagate_angles=_boolean(table, "propagate_angles", path, "errors.", True),
        angle_method=_choice(table, "angle_method", path, ANGLE_METHODS, defaults.angle_method),
        hierarchical=_boolean(table, "hierarchical", path, "errors.", True),
        sample_sd_prior=number("sample_sd_prior", defaults.sample_sd_prior, positive=True),
        repeatability=repeatability,
        repeatability_sd_prior=number(
            "repeatability_sd_prior", defaults.repeatability_sd_prior, positive=True
        ),
    )


def parse_scene(document: dict, path: Path) -> Scene:
    """Validate a parsed scene TOML document (see the module docstring for the schema)."""
    for key in document:
        if key not in _TOP_KEYS:
            raise BadInputError(
                f"unknown key (allowed: {', '.join(sorted(_TOP_KEYS))})", file=path, field=key
            )
    measurements = _string(document, "measurements", path)
    from_bsdf = is_bsdf_path(Path(measurements))
    series_table = document.get(
        "series", {BSDF_SERIES: {"quantity": "brdf"}} if from_bsdf else None
    )
    if not isinstance(series_table, dict) or not series_table:
        raise BadInputError(
            "at least one [series.NAME] table is required", file=path, field="series"
        )
    if from_bsdf and set(series_table) != {BSDF_SERIES}:
        raise BadInputError(
            f"a .BSDF table is one series, '{BSDF_SERIES}' (quantity = \"brdf\")",
            file=path,
            field="series",
        )
    bsdf = _table(document, "bsdf", path, {"keep_every_radial", "keep_every_azimuth"})
    thinning = tuple(_count(bsdf, key, path) for key in ("keep_every_radial", "keep_every_azimuth"))
    series = {}
    for name in series_table:
        table = _table(
            series_table,
            name,
            path,
            {"aperture_diameter_mm", "aperture_distance_mm", "quantity"},
            "series.",
        )
        prefix = f"series.{name}."
        try:
            quantity = _choice(table, "quantity", path, QUANTITIES, "raw_reflectance", "")
            aperture = quantity == "raw_reflectance" or "aperture_diameter_mm" in table
            series[name] = SeriesGeometry(
                _number(table, "aperture_diameter_mm", path, positive=True) if aperture else None,
                _number(table, "aperture_distance_mm", path, positive=True) if aperture else None,
                quantity,
            )
        except BadInputError as error:
            raise BadInputError(error.problem, file=path, field=prefix + str(error.field)) from None
    errors_table = document.get("errors", {})
    if not isinstance(errors_table, dict):
        raise BadInputError("expected a table [errors]", file=path, field="errors")
    errors = parse_errors(errors_table, path, tuple(series))
    model = _table(
        document, "model", path, {"fold", "out_of_plane", "family", *HemisphereConstants._fields}
    )
    family = _model_family(model, path)
    paper = _table(document, "paper_fit", path, {"alpha", "theta_s0_deg", "selection"})
    outputs = _table(
        document,
        "outputs",
        path,
        {"theta_i_deg", "tis", "maps", "tis_reference", "reference_params"},
    )
    reference_params = outputs.get("reference_params")
    if reference_params is not None and (
        not isinstance(reference_params, str) or reference_params not in PARAMETER_SETS
    ):
        raise BadInputError(
            f"unknown parameter set {reference_params!r} (known: {', '.join(PARAMETER_SETS)})",
            file=path,
            field="outputs.reference_params",
        )
    fold = _boolean(model, "fold", path, "model.", False)
    out_of_plane = _boolean(model, "out_of_plane", path, "model.", True)
    constants = HemisphereConstants(
        *(
            _number(model, name, path, default=getattr(PAPER_CONSTANTS, name))
            for name in HemisphereConstants._fields
        )
    )
    theta_i_out = outputs.get("theta_i_deg", [])
    if not isinstance(theta_i_out, list) or not all(
        isinstance(v, int | float) and not isinstance(v, bool) and 0 <= v < 90 for v in theta_i_out
    ):
        raise BadInputError(
            "expected a list of angles in [0, 90) deg", file=path, field="outputs.theta_i_deg"
        )
    prior_table = _table(document, "priors", path, set(PARAM_NAMES))
    priors = dict(DEFAULT_PRIORS)
    priors.update({name: parse_prior(name, table, path) for name, table in prior_table.items()})
    wavelength = document.get("wavelength_nm")
    studies = _parse_studies(document, path)
    scene = Scene(
        name=_scene_name(document, path),
        path=path,
        description=_string(document, "description", path, default=""),
        wavelength_nm=None if wavelength is None else _number(document, "wavelength_nm", path),
        measurements_path=(path.parent / measurements),
        series=series,
        errors=errors,
        model=ModelSettings(
            fold=fold, out_of_plane=out_of_plane, constants=constants, family=family
        ),
        paper_fit=PaperFitSettings(
            alpha=_number(paper, "alpha", path, default=4.5, positive=True),
            theta_s0_deg=_number(paper, "theta_s0_deg", path, default=-12.0),
            selection=_selection(paper, path),
        ),
        outputs=OutputSettings(
            theta_i_deg=tuple(float(v) for v in theta_i_out) if theta_i_out else None,
            tis=_boolean(outputs, "tis", path, "outputs.", True),
            maps=_boolean(outputs, "maps", path, "outputs.", True),
            tis_reference=(
                None
                if "tis_reference" not in outputs
                else path.parent / _string(outputs, "tis_reference", path)
            ),
            reference_params=reference_params,
        ),
        priors=priors,
        raytrace=_parse_raytrace(document, path, series),
        studies=studies,
        bsdf_thinning=thinning,
        instrument=_parse_instrument(document, path, series),
        design=_parse_design(document, path, series),
    )
    check_instrument(scene, scene.instrument.model, field="instrument.model")
    return scene


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
