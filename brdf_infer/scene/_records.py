"""The records of a validated scene: :class:`Scene` and the settings of its tables."""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from brdf_infer.errors import BadInputError
from brdf_infer.model import ModelFamily, family
from brdf_infer.model.error_model import ErrorSettings, value_sigma
from brdf_infer.model.params import DPHI_NAME, PAPER_CONSTANTS, PARAM_NAMES, HemisphereConstants
from brdf_infer.model.priors import DEFAULT_PRIORS, Prior
from brdf_infer.scene.design_target import DESIGN_BUDGET
from brdf_infer.tables.bsdf_measurements import is_bsdf_path, measurements_from_bsdf
from brdf_infer.tables.measurements import (
    Measurements,
    load_measurements,
    pooled_measurements,
)


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
        fold: what the instrument measured: the folding term of Eq. (10) in the likelihood's
            predictions (a scatterometer whose forward-grazing readings fold). False (the
            default): the rows are the physical BRDF. The products follow their own switch,
            :attr:`OutputSettings.fold`.
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


# what a band describes (brdf_infer.posterior._targets); "auto" picks by the samples measured
TARGETS = ("measured", "coating", "new_part")
TARGET_CHOICES = ("auto", *TARGETS)


@dataclass(frozen=True)
class OutputSettings:
    """Which products a run makes.

    Attributes:
        theta_i_deg: incidence angles of the in-plane BRDF bands [deg] (None: the measured
            ones, see :meth:`Scene.band_theta_i_deg`).
        fold: the folding term of Eq. (10) in the products (BRDF and TIS bands, hemisphere
            maps, exports, design's targets). False (the default): the physical BRDF, the
            conservative one for stray light, whatever the instrument measured
            (:attr:`ModelSettings.fold`); True only to compare with a folded measurement
            (the article's Table 3).
        tis: make the TIS band (only with the out-of-plane extension).
        maps: make the hemisphere maps (only with the out-of-plane extension).
        tis_reference: CSV of reference TIS points (theta_i_deg, tis, label), or None.
        reference_params: a named parameter set drawn beside the BRDF bands, or None.
        target: what the bands and products describe (:mod:`brdf_infer.posterior._targets`):
            ``measured``, ``coating``, ``new_part`` or ``auto`` (measured for one physical
            sample, else coating).
    """

    theta_i_deg: tuple[float, ...] | None = None
    fold: bool = False
    tis: bool = True
    maps: bool = True
    tis_reference: Path | None = None
    reference_params: str | None = None
    target: str = "auto"


@dataclass(frozen=True)
class PaperFitSettings:
    """The paper's linear regression (Sec. 4.2).

    Attributes:
        alpha: fixed exponent α [-].
        theta_s0_deg: fixed θs0 [deg].
        selection: name of the data selection (``brdf_infer.tables.selections.SELECTIONS``).
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
            (:mod:`brdf_infer.studies.sensitivity`).
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
    """The ``[design]`` table: the settings the instrument can reach and how a new row is
    taken (:mod:`brdf_infer.design`).

    Attributes:
        theta_i_deg: (low, high) incidence angles the goniometer reaches [deg].
        theta_s_deg: (low, high) signed in-plane scattering angles it reaches [deg] (> 0:
            forward side).
        step_deg: grid step in θi and θs [deg].
        source_clearance_deg: the least lab angle |θi + θs| between the camera and the
            incident beam [deg]; the camera cannot stand in the beam (θs = −θi is the
            retro-reflection direction, the source itself).
        series: the series (aperture) a new row is taken in (None: the series with the most
            rows); one without measured rows is a new series, its aperture from its
            ``[series.NAME]`` table.
        same_session: the measured series whose session new rows of that series continue
            (its reference measurement, Eq. 2, and rotation settings); None: every new row
            is a new session with a reference of its own.
        budget: rows chosen together by default.

    The defaults are a generic goniometer, not a measured one: a scene states its own.
    """

    theta_i_deg: tuple[float, float] = (10.0, 85.0)
    theta_s_deg: tuple[float, float] = (-85.0, 85.0)
    step_deg: float = 5.0
    source_clearance_deg: float = 10.0
    series: str | None = None
    same_session: str | None = None
    budget: int = DESIGN_BUDGET


@dataclass(frozen=True)
class ReferenceValue:
    """A value of the answer published elsewhere, to be placed in the posterior
    (``[reference.QUANTITY]``).

    Attributes:
        quantity: ``tis_<θi>deg`` (TIS at that incidence angle [deg], a fraction), ``pi_brdf0``
            (π·BRDF0, a fraction) or a parameter of Eq. (7) in its paper units.
        value: the published value, in the quantity's units.
        source: where it comes from (publication, section), shown beside it.

    The posterior's quantity is the run's own (a TIS with the scene's ``[model] fold``).
    """

    quantity: str
    value: float
    source: str

    @property
    def tis_angle_deg(self) -> float | None:
        """θi [deg] of a ``tis_<θi>deg`` quantity, else None."""
        return tis_angle_deg(self.quantity)


def tis_angle_deg(quantity: str) -> float | None:
    """θi [deg] named by ``tis_<θi>deg`` (e.g. ``tis_70deg`` → 70.0), else None."""
    match = re.fullmatch(r"tis_(\d+(?:\.\d+)?)deg", quantity)
    return None if match is None else float(match.group(1))


@dataclass(frozen=True)
class Campaign:
    """One measurement file of a pooled scene (``[campaigns.NAME]``): a lab, a session, an
    instrument measuring the same coating. Its series and samples are named
    ``NAME/SERIES`` and ``NAME/SAMPLE`` in the pooled table (a sample of one campaign is never
    a sample of another); its own data options of the error model are in
    :attr:`ErrorSettings.campaign_errors`.

    Attributes:
        name: the campaign's name (no ``/``).
        measurements_path: its measurement file (CSV or .BSDF).
        series: its series under their names in the file.
        bsdf_thinning: its ``[campaigns.NAME.bsdf]`` thinning of a .BSDF table.
    """

    name: str
    measurements_path: Path
    series: dict[str, SeriesGeometry]
    bsdf_thinning: tuple[int, int] = (1, 1)

    def load_measurements(self) -> Measurements:
        """The campaign's rows under their own series and sample names."""
        return read_measurements(self.measurements_path, self.series, self.bsdf_thinning)


def read_measurements(
    path: Path, series: dict[str, SeriesGeometry], thinning: tuple[int, int]
) -> Measurements:
    """A measurement table validated against its series (a .BSDF table: its BRDF values,
    thinned by ``thinning``)."""
    if is_bsdf_path(path):
        return measurements_from_bsdf(path, *thinning)
    return load_measurements(
        path,
        known_series=series,
        series_quantity={name: g.quantity for name, g in series.items()},
    )


@dataclass(frozen=True)
class Scene:
    """A validated scene. A pooled scene (:attr:`campaigns`) has its campaigns' series under
    their prefixed names and, as :attr:`measurements_path`, its first campaign's file."""

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
    references: tuple[ReferenceValue, ...] = ()
    campaigns: tuple[Campaign, ...] = ()

    @property
    def measurement_files(self) -> list[tuple[str, Path]]:
        """(what names it, path) of every measurement file: ``measurements``, or
        ``campaigns.NAME.measurements`` of each campaign."""
        if not self.campaigns:
            return [("measurements", self.measurements_path)]
        return [(f"campaigns.{c.name}.measurements", c.measurements_path) for c in self.campaigns]

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

    @property
    def dphi_free(self) -> bool:
        """Eq. (8)'s out-of-plane width is uncertain: a parameter (``dphi_scale``, the factor
        on the article's Δφ) under ``[priors.dphi_scale]``; False where that prior is fixed
        (its factor then in ``model.constants``) or the scene has no Eq. (8)."""
        return self.model.out_of_plane and not self.priors[DPHI_NAME].fixed

    def family(self, name: str | None = None) -> ModelFamily:
        """The model family ``name`` (default: ``[model] family``) with the scene's fold,
        constants and, for Eq. (7)'s, the out-of-plane width as a parameter where uncertain
        (:attr:`dphi_free`)."""
        return family(
            name or self.model.family, self.model.fold, self.model.constants, self.dphi_free
        )

    def band_theta_i_deg(self, measurements: Measurements) -> tuple[float, ...]:
        """Incidence angles of the in-plane BRDF bands [deg]: the scene's ``[outputs]
        theta_i_deg``, else every measured one, in increasing order (no cap: a table of 18
        angles of incidence has 18 bands, 18 TIS rows in the result)."""
        if self.outputs.theta_i_deg is not None:
            return self.outputs.theta_i_deg
        return tuple(float(a) for a in np.unique(measurements.theta_i_deg))

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
        BRDF values, thinned as ``[bsdf]`` says); a pooled scene's campaigns joined
        (:func:`brdf_infer.tables.measurements.pooled_measurements`)."""
        if not self.campaigns:
            return read_measurements(self.measurements_path, self.series, self.bsdf_thinning)
        parts = {}
        for campaign in self.campaigns:
            rows = campaign.load_measurements()
            own = self.errors.of_campaign(campaign.name)
            value_sigma(own, rows)  # a row without noise is named in its own file
            parts[campaign.name] = (rows, own.reflectance_rel)
        return pooled_measurements(parts)

    def check_files(self) -> None:
        """Resolve and read every file the scene names, before any work.

        Raises:
            BadInputError: a file is missing or malformed; the message names the scene, the
                key and the resolved path.
        """
        for key, path in (
            *self.measurement_files,
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


TIS_ANGLE_DEG = 70.0  # the article's TIS angle (Sec. 7), always among the reported angles [deg]


def tis_angles(scene: Scene, measurements: Measurements) -> list[float]:
    """The angles a run reports the TIS at: the scene's band angles
    (:meth:`Scene.band_theta_i_deg`) and 70° (:data:`TIS_ANGLE_DEG`), ascending [deg]."""
    return sorted({*scene.band_theta_i_deg(measurements), TIS_ANGLE_DEG})
