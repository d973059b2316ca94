"""Posterior results on disk: ArviZ InferenceData, summary and bands, written atomically."""

from __future__ import annotations

import io
import json
import time
from importlib import metadata
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import xarray as xr
from numpyro.infer import Predictive

import brdf_infer
from brdf_infer._internal import arviz as az
from brdf_infer._internal.atomic import atomic_write_bytes
from brdf_infer._internal.outlock import require_complete
from brdf_infer.errors import BadInputError
from brdf_infer.model import ModelFamily, family, run_family_name
from brdf_infer.model.params import PARAM_NAMES
from brdf_infer.posterior._blocks import factor_columns, over_draw_blocks
from brdf_infer.posterior._likelihood import disjoint_columns
from brdf_infer.posterior._loo import pointwise_loo_terms
from brdf_infer.posterior._model import NOISE_SITES, PosteriorModel
from brdf_infer.posterior._samplers import Draws
from brdf_infer.runs.folder import BANDS_FILE as BANDS_FILE  # the old name, kept
from brdf_infer.runs.folder import POSTERIOR_FILE as POSTERIOR_FILE  # the old name, kept
from brdf_infer.runs.folder import SUMMARY_FILE as SUMMARY_FILE  # the old name, kept
from brdf_infer.runs.folder import RunFolder
from brdf_infer.runs.records import Bands, PosteriorSummary
from brdf_infer.tables.measurements import Measurements
from brdf_infer.tables.screening import TableScreening

THRESHOLDS = {"r_hat": 1.01, "ess": 400, "bfmi": 0.3, "tau_multiple": 50}


def _versions() -> dict[str, str]:
    """The versions of what ran; emcee's and optimistix's from their installed metadata, as
    importing them (0.3-0.6 s for optimistix) would serve nothing else in a NUTS run."""
    import numpyro

    return {
        "brdf_infer": brdf_infer.__version__,
        "jax": jax.__version__,
        "numpyro": numpyro.__version__,
        "emcee": metadata.version("emcee"),
        "arviz": az.VERSION,
        "optimistix": metadata.version("optimistix"),
    }


def flatten_draws(sites: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Sites of shape (chain, draw, ...) as (chain × draw, ...)."""
    return {k: v.reshape(v.shape[0] * v.shape[1], *v.shape[2:]) for k, v in sites.items()}


FLOAT64_TERMS_BYTES = 2**28  # pointwise terms above 256 MiB are held in float32
STORED_TERMS_VALUES = 10**6  # log_likelihood kept in posterior.nc up to chains × draws × rows
PREDICTIVE_VALUES = 10**6  # replicated rows kept in posterior.nc: at most these many values
PREDICTIVE_MIN_DRAWS = 20  # ... but at least these many draws (thinned evenly in each chain)
# PSIS-LOO from at most these many leave-one-out terms (chains × draws × rows; 4000 draws up
# to 4194 rows) ... but at least LOO_MIN_DRAWS a chain: on a whole table the terms of 1000
# draws cost 45 s and their Pareto smoothing 25 s instead of 127 s and 97 s
LOO_VALUES = 2**24
LOO_MIN_DRAWS = 250


def loo_terms(model, sites: dict[str, np.ndarray]):
    """(log p(yᵢ | y₋ᵢ, θ), P(ỹᵢ ≤ yᵢ | y₋ᵢ, θ)) of every draw and row, each (chain, draw, row),
    for any posterior model with ``draw_parts`` and ``data`` (every family's).

    The leave-one-out conditionals of the model's (possibly correlated) normal likelihood
    (:mod:`brdf_infer.posterior._loo`); for independent rows the ordinary pointwise terms.
    Computed a block of draws at a time (:mod:`brdf_infer.posterior._blocks`); held in float32
    where the two arrays would exceed :data:`FLOAT64_TERMS_BYTES` each.
    """
    chains, n_draws = next(iter(sites.values())).shape[:2]
    y = model.data.rows.log_reflectance
    rows = int(np.shape(y)[-1])
    disjoint = disjoint_columns(model.data)

    def terms(block):
        parts = model.draw_parts(block)
        return pointwise_loo_terms(y, parts.mean, parts.factor, parts.diagonal, disjoint=disjoint)

    dtype = np.float64 if chains * n_draws * rows * 8 <= FLOAT64_TERMS_BYTES else np.float32
    columns = factor_columns(model.data.noise)
    log_lik, cdf = over_draw_blocks(terms, flatten_draws(sites), rows, columns, dtype)
    shape = (chains, n_draws, rows)
    return log_lik.reshape(shape), cdf.reshape(shape)


def thinned_draws(
    n_draws: int,
    rows: int,
    chains: int,
    values: int = PREDICTIVE_VALUES,
    minimum: int = PREDICTIVE_MIN_DRAWS,
) -> np.ndarray:
    """Indices of the draws of each chain whose replicated data posterior.nc keeps (or, with
    :data:`LOO_VALUES` and :data:`LOO_MIN_DRAWS`, whose leave-one-out terms PSIS-LOO reads):
    every draw where chains × draws × rows ≤ ``values``, else evenly spaced ones, at least
    ``minimum`` a chain."""
    keep = max(minimum, values // max(1, chains * rows))
    if keep >= n_draws:
        return np.arange(n_draws)
    return np.unique(np.linspace(0, n_draws - 1, keep).round().astype(int))


def loo_draws(n_draws: int, rows: int, chains: int) -> np.ndarray:
    """Indices of the draws of each chain whose leave-one-out terms PSIS-LOO, the exact-LOO
    refits and the answer records read (:func:`thinned_draws` with :data:`LOO_VALUES` and
    :data:`LOO_MIN_DRAWS`: every draw of a small run)."""
    return thinned_draws(n_draws, rows, chains, LOO_VALUES, LOO_MIN_DRAWS)


def loo_sites(sites: dict[str, np.ndarray], rows: int) -> tuple[dict[str, np.ndarray], float]:
    """``sites`` (chain, draw, ...) at :func:`loo_draws` and the thinning factor, draws over
    draws kept (1: every draw, ``sites`` themselves)."""
    chains, count = np.shape(next(iter(sites.values())))[:2]
    kept = loo_draws(count, rows, chains)
    if kept.size == count:
        return sites, 1.0
    return {name: values[:, kept] for name, values in sites.items()}, count / kept.size


def replicated_data(model: PosteriorModel, sites: dict[str, np.ndarray], seed: int) -> np.ndarray:
    """One replicated data set (ln R of every row) per draw that posterior.nc keeps
    (:func:`thinned_draws`: every draw of a small run), shape (chain, kept draw, row)."""
    chains, n_draws = next(iter(sites.values())).shape[:2]
    rows = int(np.shape(model.data.rows.log_reflectance)[-1])
    keep = thinned_draws(n_draws, rows, chains)
    kept = {k: np.asarray(v)[:, keep] for k, v in sites.items() if k != "obs"}
    flat = {k: jnp.asarray(v) for k, v in flatten_draws(kept).items()}

    def draw(key, samples, data):  # data and draws as arguments: compiled once per shape
        predictive = Predictive(model, posterior_samples=samples, return_sites=["obs"])
        return predictive(key, data, mode="predict")["obs"]

    replicated = jax.jit(draw)(jax.random.PRNGKey(seed + 7), flat, model.data)
    return np.asarray(replicated).reshape(chains, keep.size, -1)


def stored_log_likelihood(log_lik: np.ndarray | None) -> dict[str, dict[str, np.ndarray]]:
    """The ``log_likelihood`` group posterior.nc keeps: the pointwise terms of a run of at
    most :data:`STORED_TERMS_VALUES` values (for ``az.loo`` on the file), none for a larger
    one, whose PSIS-LOO is in summary.json's ``predictive`` record."""
    if log_lik is None or log_lik.size > STORED_TERMS_VALUES:
        return {}
    return {"log_likelihood": {"obs": log_lik}}


def sample_index(model: PosteriorModel) -> np.ndarray:
    """Index of each row's physical sample in ``model.sample_names``."""
    names = model.sample_names
    return np.array([names.index(str(s)) for s in model.row_samples], dtype=int)


def inference_data(
    model: PosteriorModel, draws: Draws, seed: int, log_lik: np.ndarray | None
) -> az.InferenceData:
    """ArviZ InferenceData with posterior, sample_stats, log_likelihood (``log_lik``: the
    leave-one-out conditionals of :func:`loo_terms` of every draw, for PSIS-LOO; only for a
    run of at most :data:`STORED_TERMS_VALUES` values; None: none), posterior_predictive (the draws
    :func:`thinned_draws` keeps, their indices as the group's ``draw`` coordinate),
    observed_data and constant_data; the six ``Params`` fields in paper units in the
    posterior."""
    rows, noise = model.data.rows, model.data.noise
    idata = az.from_dict(
        posterior=dict(draws.sites),
        sample_stats=draws.stats,
        **stored_log_likelihood(log_lik),
        posterior_predictive={"obs": replicated_data(model, draws.sites, seed)},
        observed_data={"obs": np.asarray(rows.log_reflectance)},
        constant_data={
            "theta_i_deg": np.asarray(rows.theta_i_deg),
            "theta_s_deg": np.asarray(rows.theta_s_deg),
            "log_aperture": np.asarray(rows.log_aperture),
            "sigma_row": np.asarray(noise.sigma_row),
            "sample_index": sample_index(model),
            "series_index": np.asarray(model.row_series, dtype=int),
        },
        dims={
            "obs": ["row"],
            "theta_i_deg": ["row"],
            "theta_s_deg": ["row"],
            "log_aperture": ["row"],
            "sigma_row": ["row"],
            "sample_index": ["row"],
            "series_index": ["row"],
            "linear_std": ["coefficient"],
            "rotation_error_std": ["rotation_setting"],
            "camera_error_std": ["row"],
            "rotation_alone_error_std": ["row"],
        },
    )
    sizes = idata.posterior.sizes
    kept = thinned_draws(sizes["draw"], int(np.shape(rows.theta_i_deg)[-1]), sizes["chain"])
    if kept.size < sizes["draw"]:  # the replicated draws' own indices
        idata.posterior_predictive = idata.posterior_predictive.assign_coords(draw=kept)
    scene = model.scene
    idata.posterior.attrs.update(
        {
            "scene": scene.name,
            "model": model.family.name,
            "instrument": scene.instrument.model,
            "scene_file": str(scene.path.resolve()),  # readers may run anywhere
            "scene_toml": scene.path.read_text(),
            "sampler": draws.sampler,
            "settings": json.dumps(draws.settings),
            "seed": seed,
            "fold": int(scene.model.fold),  # the likelihood's: what the rows measured
            "products_fold": int(scene.outputs.fold),  # the products' (bands, exports)
            "constants": json.dumps(scene.model.constants._asdict()),
            "error_model": json.dumps(scene.errors.describe()),
            "free_parameters": json.dumps(list(scene.free_parameters)),
            "samples": json.dumps(list(model.sample_names)),
            "reparametrised": int(model.whiten),
            "versions": json.dumps(_versions()),
            "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        }
    )
    return idata


# the run's own rows (posterior.nc group), so that its readers need no measurement file
MEASUREMENTS_GROUP = "measurements"
_ROW_COLUMNS = ("series", "sample", "theta_i_deg", "theta_s_deg", "reflectance")


def store_measurements(idata: az.InferenceData, measurements: Measurements) -> None:
    """Add the rows the run sampled to ``idata`` (group ``measurements``: every column of
    the table, its quantity, its file, and what reading a .BSDF table left out), so that
    the run's readers (report, design) work after the measurement file is moved or deleted
    (:func:`run_measurements`)."""
    columns = {name: np.asarray(getattr(measurements, name)) for name in _ROW_COLUMNS}
    columns["series"] = columns["series"].astype(str)
    columns["sample"] = columns["sample"].astype(str)
    for name in ("reflectance_err", "phi_s_deg"):
        if getattr(measurements, name) is not None:
            columns[name] = np.asarray(getattr(measurements, name), float)
    screening = measurements.screening
    if screening is not None:
        columns["zero_directions"] = np.asarray(screening.zero_directions, float)
    attrs = {"quantity": measurements.quantity, "path": str(measurements.path)}
    if screening is not None:
        kept = ("zero_cells", "detection_limit", "below_horizon", "dropouts")
        attrs["screening"] = json.dumps({k: screening.as_json()[k] for k in kept})
    group = xr.Dataset(
        {
            name: (("zero_cell", "angle") if name == "zero_directions" else ("row",), values)
            for name, values in columns.items()
        },
        attrs=attrs,
    )
    idata.add_groups({MEASUREMENTS_GROUP: group})


def run_measurements(idata: az.InferenceData) -> Measurements | None:
    """The rows a run sampled (:func:`store_measurements`); None for a run written before
    they were kept."""
    if MEASUREMENTS_GROUP not in idata.groups():
        return None
    group = idata[MEASUREMENTS_GROUP]
    column = {name: np.asarray(group[name]) for name in group.data_vars}
    screening = None
    if "screening" in group.attrs:
        record = json.loads(group.attrs["screening"])
        screening = TableScreening(
            zero_cells=int(record["zero_cells"]),
            detection_limit=float(record["detection_limit"]),
            below_horizon=int(record["below_horizon"]),
            dropouts=tuple(record["dropouts"]),
            zero_directions=column.get("zero_directions", np.zeros((0, 3))).reshape(-1, 3),
        )
    return Measurements(
        path=Path(str(group.attrs.get("path", ""))),
        series=column["series"].astype(str),
        sample=column["sample"].astype(str),
        theta_i_deg=column["theta_i_deg"].astype(float),
        theta_s_deg=column["theta_s_deg"].astype(float),
        reflectance=column["reflectance"].astype(float),
        reflectance_err=column.get("reflectance_err"),
        quantity=str(group.attrs.get("quantity", "raw_reflectance")),
        phi_s_deg=column.get("phi_s_deg"),
        screening=screening,
    )


# the Laplace sampler's importance-sampling record (brdf_infer.posterior._laplace)
IMPORTANCE_KEYS = ("pareto_k", "ess", "proposals", "distinct_draws", "adaptations")


def diagnostics(
    idata: az.InferenceData,
    draws: Draws,
    parameters: tuple[str, ...] = PARAM_NAMES,
    fixed: tuple[str, ...] = (),
) -> dict[str, Any]:
    """R-hat, bulk/tail ESS per sampled physical parameter (``parameters``, in their units)
    and learned noise scale (``fixed`` parameters are listed apart), divergences and BFMI
    (NUTS; with the reason where Laplace was refused), the importance weights' Pareto k and
    Kish ESS (Laplace; that ESS bounds ArviZ's, and R-hat between its exchangeable chains is
    recorded but not checked), run length in autocorrelation times (emcee),
    and the list of thresholds that
    failed (:data:`THRESHOLDS`). A statistic that is undefined (a chain that never moved)
    counts as failed."""
    sampled = [name for name in parameters if name not in fixed]
    sampled += [name for name in NOISE_SITES if name in idata.posterior]
    summary = az.summary(idata, var_names=sampled, kind="all", round_to="none")

    def worst(column: str, largest: bool) -> float:
        values = np.asarray(summary[column], float)
        if np.any(~np.isfinite(values)):
            return float("nan")
        return float(values.max() if largest else values.min())

    result: dict[str, Any] = {
        "r_hat_max": worst("r_hat", True),
        "ess_bulk_min": worst("ess_bulk", False),
        "ess_tail_min": worst("ess_tail", False),
        "parameters": {
            name: {column: float(summary.loc[name, column]) for column in summary.columns}
            for name in sampled
        },
        "fixed": list(fixed),
    }
    if draws.sampler == "nuts":
        result["divergences"] = int(np.sum(draws.stats["diverging"]))
        result["bfmi_min"] = float(np.min(az.bfmi(idata)))
        if "laplace_refused" in draws.extra:
            result["laplace_refused"] = draws.extra["laplace_refused"]
    elif draws.sampler == "laplace":
        # resampled draws repeat, so ArviZ's ESS of them overstates; Kish's of the weights
        importance = {key: draws.extra[key] for key in IMPORTANCE_KEYS}
        result["importance"] = importance
        result["ess_bulk_min"] = min(result["ess_bulk_min"], importance["ess"])
        result["ess_tail_min"] = min(result["ess_tail_min"], importance["ess"])
    else:
        result["steps_per_autocorrelation_time"] = draws.extra["steps_per_autocorrelation_time"]
        result["autocorrelation_time_max"] = float(np.max(draws.extra["autocorrelation_time"]))
        result["acceptance_fraction"] = draws.extra["acceptance_fraction"]
        result["thin"] = draws.extra["thin"]
    failures = []
    if draws.sampler != "laplace" and not result["r_hat_max"] <= THRESHOLDS["r_hat"]:
        failures.append(f"R-hat {result['r_hat_max']:.3f} > {THRESHOLDS['r_hat']}")
    for kind in ("bulk", "tail"):
        if not result[f"ess_{kind}_min"] >= THRESHOLDS["ess"]:
            failures.append(f"{kind} ESS {result[f'ess_{kind}_min']:.0f} < {THRESHOLDS['ess']}")
    if result.get("divergences", 0) > 0:
        failures.append(f"{result['divergences']} divergent transitions")
    if result.get("bfmi_min", 1.0) < THRESHOLDS["bfmi"]:
        failures.append(f"BFMI {result['bfmi_min']:.2f} < {THRESHOLDS['bfmi']}")
    if result.get("steps_per_autocorrelation_time", np.inf) < THRESHOLDS["tau_multiple"]:
        failures.append(
            f"emcee ran {result['steps_per_autocorrelation_time']:.0f} autocorrelation "
            f"times < {THRESHOLDS['tau_multiple']}"
        )
    result["failures"] = failures
    return result


def netcdf_bytes(idata: az.InferenceData) -> bytes:
    """``idata`` as the netCDF file ``InferenceData.to_netcdf`` writes (h5netcdf, every group,
    numbers compressed), built in memory.

    In memory, so that writing it to disk is one plain atomic write: when HDF5 itself fails
    to write a file (a full disk), its half-open file makes the process crash later (h5py
    3.16 frees it with a segmentation fault), after the error was reported.
    """
    import xarray as xr

    buffer = io.BytesIO()
    mode = "w"
    if idata.attrs:
        xr.Dataset(attrs=idata.attrs).to_netcdf(buffer, mode=mode, engine="h5netcdf", group="/")
        mode = "a"
    for group in idata.groups():
        data = getattr(idata, group)
        encoding = {
            name: {"zlib": True}
            for name, values in data.variables.items()
            if np.issubdtype(values.dtype, np.number) or values.dtype == bool
        }
        data.to_netcdf(buffer, mode=mode, group=group, engine="h5netcdf", encoding=encoding)
        mode = "a"
    return buffer.getvalue()


def write_inference_data(idata: az.InferenceData, path: Path) -> None:
    """Write ``idata`` to ``path`` as netCDF, atomically (:func:`netcdf_bytes`).

    Raises:
        OSError: the write failed (naming ``path``; ``path`` is unchanged).
    """
    atomic_write_bytes(path, netcdf_bytes(idata))


def write_results(
    out: Path, idata: az.InferenceData, summary: PosteriorSummary, bands: Bands
) -> None:
    """posterior.nc, summary.json and bands.json into ``out``, each atomically."""
    folder = RunFolder(out)
    folder.path.mkdir(parents=True, exist_ok=True)
    write_inference_data(idata, folder.posterior_file)
    folder.write_bands(bands)
    folder.write_summary(summary)


def run_posterior_group(run: Path):
    require_complete(run)
    path = RunFolder(run).posterior_file
    if not path.is_file():
        raise BadInputError("no posterior.nc here (run 'brdf-infer posterior' first)", file=run)
    try:
        return az.from_netcdf(path).posterior, path
    except (OSError, ValueError) as error:
        raise BadInputError(f"cannot read: {error}", file=path) from None


def run_fold(posterior) -> bool:
    """The products' fold switch of the run whose ``posterior`` group this is: its scene's
    ``[outputs] fold`` (Eq. 10 in its bands and exports; runs written before the two
    switches had one, ``[model] fold``, for the likelihood and the products alike)."""
    return bool(int(posterior.attrs.get("products_fold", posterior.attrs.get("fold", 0))))


def load_run_family(
    run: Path, fold: bool | None = None
) -> tuple[ModelFamily, dict[str, np.ndarray]]:
    """(the run's model family, every draw of its physical parameters) for a posterior run
    of any family (``fold``: ``strumik2024`` with or without Eq. 10; None: the run's own
    switch, :func:`run_fold`).

    Raises:
        BadInputError: no readable posterior.nc in ``run``, or one without its parameters.
    """
    posterior, path = run_posterior_group(run)
    return family_draws(posterior, fold, path)


def family_draws(
    posterior, fold: bool | None = None, path: Path | None = None
) -> tuple[ModelFamily, dict[str, np.ndarray]]:
    """(model family, every draw of its physical parameters) of a run's ``posterior`` group
    (its attribute ``model``; runs without it are ``strumik2024``); ``fold`` as in
    :func:`load_run_family`.

    Raises:
        BadInputError: an unknown family, or a group without its parameters (naming ``path``).
    """
    from brdf_infer.model.params import DPHI_NAME, HemisphereConstants

    name = run_family_name(posterior.attrs)
    fold = run_fold(posterior) if fold is None else fold
    try:
        constants = HemisphereConstants(**json.loads(posterior.attrs["constants"]))
        member = family(name, fold, constants, DPHI_NAME in posterior)
    except (KeyError, TypeError, ValueError):
        raise BadInputError(f"unknown model {name!r} or constants in the run", file=path) from None
    missing = [p for p in member.parameters if p not in posterior]
    if missing:
        raise BadInputError(f"posterior lacks {', '.join(missing)}", file=path)
    return member, {p: np.asarray(posterior[p]).reshape(-1) for p in member.parameters}
