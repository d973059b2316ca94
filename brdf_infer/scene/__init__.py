"""Scenes: a TOML file naming the measurements, the geometry of each series, the error model
and the analysis settings (README, "Your own data"). Built-in scenes ship in ``data/``.

Schema (keys other than these are errors; defaults in brackets)::

    name = "my-coating"                      # required
    description = "..."                      # [""]
    wavelength_nm = 121.6                    # [unset]
    measurements = "my_measurements.csv"     # required, relative to the scene file (or
                                             #   [campaigns.NAME] tables in its place and
                                             #   [series]'s: brdf_infer.scene._campaigns)
    [series.NAME]                            # one table per series named in the CSV
    aperture_diameter_mm = 7.2               # required, > 0
    aperture_distance_mm = 103.8             # required, > 0
    [errors]                                 # brdf_infer.model.error_model explains the model
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
    hierarchical = true                      # [true] per-sample random effect u_j ~ N(0, τ)
    sample_sd = "learned"                    # ["learned"] or a stated τ [ln R], which needs
    sample_sd_source = "..."                 #   its source in words
    sample_sd_prior = 0.2                    # [0.2] half-normal scale of τ's prior [ln R]
    sample_sd_from = "reports/lya"           # [none] a run of the same coating: its τ
                                             #   posterior (a kernel density) is τ's prior
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
    selection = "paper"                      # ["paper"] see brdf_infer.tables.selections.SELECTIONS
    [outputs]
    theta_i_deg = [18, 45, 60, 75, 80]       # [every measured θi] BRDF bands [deg]
    tis = true                               # [true] TIS band (needs out_of_plane)
    maps = true                              # [true] hemisphere maps (needs out_of_plane)
    tis_reference = "reference.csv"          # [none] theta_i_deg,tis,label points to compare
    reference_params = "uv-paper"            # [none] parameter set drawn beside the bands
    target = "auto"                          # ["auto"] what the bands describe: "measured"
                                             #   (the samples measured), "coating" (their
                                             #   population), "new_part" (an unmeasured part);
                                             #   auto: measured for one sample, else coating
    [priors.NAME]                            # NAME in brdf0, a1, a2, a3, alpha, theta_s0
    kind = "normal"                          # [model.priors.DEFAULT_PRIORS] see priors.py
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
                                             #   assumption changed (brdf_infer.studies.sensitivity)
    instruments = ["aperture", "image"]      # [] posteriors under other instrument models
    raytrace = true                          # [false] ray-trace the posterior ([raytrace])
    compare = ["strumik2024", "abg"]         # [] model families compared by PSIS-LOO
    design = "tis:70"                        # [unset] where to measure next for this target
                                             #   (brdf_infer.design; tis:THETA, pi_brdf0, ...)
    [design]                                 # what the goniometer reaches, how a new row is
                                             #   taken (brdf-infer design)
    theta_i_deg = [18.0, 80.0]               # [[10, 85]] θi it reaches [deg]
    theta_s_deg = [-85.0, 85.0]              # [[-85, 85]] signed in-plane θs it reaches [deg]
    step_deg = 5.0                           # [5] grid step [deg]
    source_clearance_deg = 36.0              # [10] least lab angle |θi + θs| between the
                                             #   camera and the incident beam [deg]
    series = "II"                            # [the series with the most rows] the series
                                             #   (aperture) a new row is taken in; one without
                                             #   rows: a new series ([series.NAME] aperture)
    same_session = "II"                      # [unset: a new session, its own reference]
                                             #   new rows of this series continue its session
    budget = 3                               # [3] rows chosen together
    [reference.tis_70deg]                    # a published value to place in the posterior:
    value = 0.058                            #   tis_<θi>deg, pi_brdf0 or a parameter of
    source = "Strumik et al. 2024, Sec. 7"   #   Eq. (7), in its units; value and source
"""

from brdf_infer.scene._errors import parse_errors
from brdf_infer.scene._load import BUILTIN_SCENES, DEFAULT_SCENE, load_scene, scene_file
from brdf_infer.scene._parse import parse_scene
from brdf_infer.scene._records import (
    TARGETS,
    TIS_ANGLE_DEG,
    DesignSettings,
    InstrumentSettings,
    ModelSettings,
    OutputSettings,
    PaperFitSettings,
    RaytraceSettings,
    ReferenceValue,
    Scene,
    SeriesGeometry,
    Studies,
    tis_angles,
)
from brdf_infer.scene._setups import check_instrument

__all__ = [
    "BUILTIN_SCENES",
    "DEFAULT_SCENE",
    "TARGETS",
    "TIS_ANGLE_DEG",
    "DesignSettings",
    "InstrumentSettings",
    "ModelSettings",
    "OutputSettings",
    "PaperFitSettings",
    "RaytraceSettings",
    "ReferenceValue",
    "Scene",
    "SeriesGeometry",
    "Studies",
    "check_instrument",
    "load_scene",
    "parse_errors",
    "parse_scene",
    "scene_file",
    "tis_angles",
]
