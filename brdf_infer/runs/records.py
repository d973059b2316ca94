"""The records a posterior run passes on: ``summary.json`` and ``bands.json``, typed.

They are JSON on disk and dicts in memory (a notebook indexes ``run.summary["tis_70deg"]``
as it reads the file); these ``TypedDict`` classes say which keys each holds, of what type
and in which unit, for the posterior that writes them and for the CLI, the report, the verdict,
batch and the studies that read them. Keys a sampler or family has only sometimes are marked
``NotRequired``. The test suite holds real runs' files (NUTS, emcee) against them.
Units: angles in degrees, BRDF in sr⁻¹, TIS and reflectance as fractions, noise scales in
ln R, times in seconds.
"""

# no ``from __future__ import annotations``: TypedDict reads NotRequired from real types
from typing import Any, NotRequired, TypedDict


class Interval(TypedDict):
    """Posterior median and 95 % interval of one quantity."""

    median: float
    lo95: float
    hi95: float


class Band(Interval):
    """Median, 68 % and 95 % intervals of one quantity."""

    lo68: float
    hi68: float


class Diagnostics(TypedDict):
    """Sampler health: ArviZ's R-hat and ESS over the sampled parameters, the failures in
    words; NUTS adds divergences and BFMI (and why Laplace was refused, where it was),
    Laplace its importance weights' record, emcee its autocorrelation time."""

    r_hat_max: float
    ess_bulk_min: float
    ess_tail_min: float
    parameters: dict[str, dict[str, float]]  # ArviZ's summary row per parameter
    fixed: list[str]  # parameters the scene fixes (not sampled)
    failures: list[str]
    divergences: NotRequired[int]  # NUTS
    bfmi_min: NotRequired[float | None]  # NUTS
    laplace_refused: NotRequired[str]  # NUTS after a refused Laplace approximation
    # Laplace: pareto_k, ess (Kish), proposals, distinct_draws, adaptations
    importance: NotRequired[dict[str, float]]
    steps_per_autocorrelation_time: NotRequired[float]  # emcee
    autocorrelation_time_max: NotRequired[float]  # emcee
    acceptance_fraction: NotRequired[float]  # emcee
    thin: NotRequired[int]  # emcee


class Predictive(TypedDict):
    """PSIS-LOO and the LOO-PIT of every row."""

    elpd_loo: float
    se: float
    elpd_loo_mcse: NotRequired[float | None]  # its Monte Carlo standard error
    p_loo: float
    pareto_k_max: float
    pareto_k_high: int  # rows above pareto_k_limit, those refitted aside
    # min(1 − 1/log₁₀ S, 0.7) of the S draws PSIS-LOO read (runs before it: 0.7 implied)
    pareto_k_limit: NotRequired[float]
    pareto_k: NotRequired[list[float]]  # every row's (runs written before it lack it)
    # the rows above pareto_k_limit: row, series, sample, theta_i_deg, theta_s_deg, [phi_s_deg], k
    pareto_k_rows: NotRequired[list[dict[str, Any]]]
    # rows above pareto_k_limit whose terms a refit without them computed exactly (the fields of
    # pareto_k_rows and elpd_exact); pareto_k_high and pareto_k_rows leave them out
    loo_refit_rows: NotRequired[list[dict[str, Any]]]
    loo_pit: list[float]
    loo_pit_ks_p: float


class ModelCheckEntry(TypedDict):
    """One check of the model against the rows (brdf_infer.posterior._model_check)."""

    name: str  # fit_repeatability, fit_chi2, fit_residual_trend, loo_pit, residual_trend, …
    statistic: float | None  # the test's statistic (None: no test)
    p: float | None  # its p-value (None: no test)
    ok: bool  # passed (p ≥ 0.001)
    words: str  # what it found, in words
    detectable: str  # what it could detect (80 % power at p < 0.001), in words


class ModelCheck(TypedDict):
    """Whether the data reject the model: every check, and what to try where one failed."""

    ok: bool
    checks: list[ModelCheckEntry]
    next: NotRequired[list[str]]  # what helps, most specific first (where a check failed)


class VerdictRecord(TypedDict):
    """The run's one verdict (:class:`brdf_infer.verdict.Verdict`)."""

    ok: bool
    lines: list[str]  # the failed checks
    facts: NotRequired[list[str]]  # what a reader must know, no failures (older runs lack it)
    text: str


class VariantWidth(TypedDict):
    """A headline 95 % interval under an alternative: one assumption of the model removed."""

    lo95: float | None  # None: unreliable (k̂ above its limit, no refit)
    hi95: float | None
    mcse_lo95: NotRequired[float | None]  # the ends' Monte Carlo standard errors
    mcse_hi95: NotRequired[float | None]
    ratio: float | None  # its width over the run's
    # 1 − ratio² where the alternative is narrower (None: wider, or unreliable), the part of the
    # interval's variance the assumption carries (sources adding in quadrature), and its MC error
    variance_share: NotRequired[float | None]
    variance_share_mcse: NotRequired[float | None]
    # PSIS-LOO of the alternative less the run's, and its standard error (None: not computed)
    delta_elpd: NotRequired[float | None]
    delta_elpd_se: NotRequired[float | None]
    pareto_k: float  # of the importance weights to the variant
    method: str  # "psis" (reweighted), "refit" (sampled anew) or "unreliable"
    words: str  # the assumption in words
    refit: NotRequired[dict[str, Any]]  # a refit's settings


class PriorInterval(TypedDict):
    """The prior predictive 95 % interval of a quantity and its probability above 1."""

    lo95: float
    hi95: float
    p_above_1: float


class Width(TypedDict):
    """What carries one headline quantity's 95 % width (brdf_infer.posterior._width)."""

    lo95: float
    hi95: float
    mcse_lo95: NotRequired[float]  # the ends' Monte Carlo standard errors
    mcse_hi95: NotRequired[float]
    prior: PriorInterval
    # per assumption: calibration, sample_effect, angle_errors, out_of_plane
    without: dict[str, VariantWidth]
    without_note: NotRequired[str]  # why no variant was computed


class Learned(TypedDict):
    """Whether the data contract a parameter or noise scale (brdf_infer.posterior._learned)."""

    contraction: float  # 1 − var_post / var_prior on its prior's coordinate
    prior_sensitivity: float | None  # power-scaling sensitivity to the prior
    learned: bool  # contraction ≥ 0.5
    prior_sensitive: bool  # prior_sensitivity ≥ 0.05
    coordinate: str  # the site the prior is written on
    prior: str  # the prior in words
    words: str  # "learned", "learned, prior-sensitive (…)" or "set by its prior (…)"


class Reference(TypedDict):
    """A scene's published value placed in the posterior."""

    quantity: str  # tis_<θi>deg, pi_brdf0 or a parameter
    value: float
    source: str
    posterior_quantile: float  # share of the draws below the value
    quantile_mcse: NotRequired[float]  # its Monte Carlo standard error (older runs lack it)
    place: NotRequired[str]  # "inside", "outside" or "at the edge" (within 2 MC errors)
    inside95: bool  # place == "inside"


class TargetAnswer(TypedDict):
    """One target's headline (:mod:`brdf_infer.posterior._targets`): 95 % intervals."""

    question: str  # the question it answers, in words
    tis_70deg: Interval | None  # None: the run has no TIS
    pi_brdf0: Interval | None  # None: not Eq. (7)'s family
    per_sample: NotRequired[dict[str, dict[str, Interval | None]]]  # measured, several samples


class Targets(TypedDict):
    """Which coating the answer is for: the sample(s) measured, the coating, a new part."""

    chosen: str  # the target of the bands, tis_70deg and pi_brdf0
    tau_source: str  # where the spread between parts, τ, comes from
    measured: TargetAnswer
    coating: TargetAnswer
    new_part: TargetAnswer


class CalibrationEffect(TypedDict):
    """One calibration factor κ_g learned (:mod:`brdf_infer.posterior._campaigns`) [ln R]."""

    name: str  # the group: its series, or "series, sample"
    prior_sd: float  # σ_cal
    median: float
    lo95: float
    hi95: float
    sd: float  # posterior sd
    sd_ratio: float | None  # sd / σ_cal (None without a calibration)


class CampaignRecord(TypedDict):
    """One campaign of a pooled scene (:mod:`brdf_infer.posterior._campaigns`)."""

    measurements: str  # its file
    rows: int
    samples: list[str]  # its samples, as the pooled table names them
    errors: dict[str, Any]  # its own data options of the error model
    elpd_loo: float  # its rows' share of the run's PSIS-LOO elpd
    se: float | None  # √n × the sd of its rows' terms (None: one row)
    loo_pit_ks_p: float  # Kolmogorov–Smirnov p of its rows' LOO-PIT


class Dropout(TypedDict):
    """One dropout of a .BSDF table, left out (:mod:`brdf_infer.tables.screening`)."""

    theta_i_deg: float
    theta_s_deg: float  # signed in the plane of incidence [deg]
    phi_s_deg: NotRequired[float]  # out-of-plane rows only [deg]
    value: float  # [sr⁻¹]
    neighbours: float  # the median of its table neighbours [sr⁻¹]


class TableRecord(TypedDict):
    """What reading a .BSDF table left out, by rule (:mod:`brdf_infer.tables.screening`)."""

    zero_cells: int
    detection_limit: float  # the table's smallest positive value [sr⁻¹]
    below_horizon: int
    dropouts: list[Dropout]
    zero_rule: str
    dropout_rule: str


class PosteriorSummary(TypedDict):
    """``summary.json``: what ran, the answer and how far to trust it."""

    scene: str
    model: str  # the model family
    instrument: str
    sampler: str  # "nuts", "laplace" or "emcee"
    settings: dict[str, Any]  # the sampler's settings (chains, draws, seed, …)
    error_model: dict[str, Any]  # the scene's [errors], as used
    options: dict[str, Any]  # {"reparametrised": whitened coordinates used}
    n_points: int
    fold: bool  # Eq. (10) in the bands and the TIS (the products: [outputs] fold)
    likelihood_fold: NotRequired[bool]  # Eq. (10) in what the rows measured ([model] fold)
    median: dict[str, float]  # posterior median of each physical parameter
    units: dict[str, str]
    noise: dict[str, Interval]  # learned noise scales [ln R]
    diagnostics: Diagnostics
    predictive: Predictive
    model_check: NotRequired[ModelCheck]  # whether the data reject the model
    calibration_effects: NotRequired[list[CalibrationEffect]]  # each κ_g learned
    campaigns: NotRequired[dict[str, CampaignRecord]]  # a pooled scene's campaigns
    target: NotRequired[str]  # what tis_70deg, pi_brdf0 and the bands describe (older: coating)
    tis_70deg: Band | None  # TIS at θi = 70° (None: the run has no TIS band)
    pi_brdf0: Interval | None  # π·BRDF0, Eq. (7)'s near-normal TIS (None: other families)
    # tis_<θi>deg at the band angles, 70° and the references' angles; pi_brdf0
    width: NotRequired[dict[str, Width]]
    learned: NotRequired[dict[str, Learned]]  # per free parameter and learned noise scale
    reference: NotRequired[list[Reference]]  # the scene's [reference] values
    targets: NotRequired[Targets]  # the three targets' headline and τ's source
    seconds: dict[str, Any]  # sampling, compile, after_sampling (per step), total
    forced: list[str]  # plausibility checks the run went past
    # a .BSDF table's zero cells and dropouts left out, by rule (brdf_infer.tables.screening)
    table: NotRequired[TableRecord]
    fingerprint: dict[str, str]  # what ran, for a resume
    verdict: VerdictRecord


class BandLists(TypedDict):
    """Median, 68 % and 95 % intervals over a band's angles."""

    median: list
    lo68: list
    hi68: list
    lo95: list
    hi95: list


class BrdfBand(BandLists):
    """The in-plane BRDF band [sr⁻¹]: one list per θi of values over θs."""

    theta_i_deg: list[float]
    theta_s_deg: list[float]


class TisBand(BandLists):
    """The TIS band over θi; ``draws``: how many draws, where not every draw."""

    theta_i_deg: list[float]
    draws: NotRequired[int]


class Bands(TypedDict):
    """``bands.json``: the bands of a run."""

    fold: bool
    target: NotRequired[str]  # measured, coating or new_part (older runs: coating)
    brdf_inplane: BrdfBand
    tis: NotRequired[TisBand]  # where the run makes a TIS
    pi_brdf0: NotRequired[Band]  # Eq. (7)'s family
