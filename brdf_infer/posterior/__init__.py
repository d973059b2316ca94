"""Posterior over the six parameters of Eq. (7), or of another BRDF family's: NumPyro NUTS and
emcee from one model, with ArviZ diagnostics and credible bands for the BRDF and the TIS."""

import warnings

from tqdm import TqdmWarning

# NumPyro imports tqdm.auto, which in a Jupyter kernel without ipywidgets warns "IProgress not
# found"; NumPyro's progress bars are never shown here (ours are tqdm's console bars, on
# stderr), so the warning says nothing about this package: imported once without it
with warnings.catch_warnings():
    warnings.filterwarnings("ignore", "IProgress not found", TqdmWarning)
    import numpyro.util  # noqa: F401

from brdf_infer.posterior._bands import (
    FAMILY_TIS_DRAWS,
    QUANTILES,
    draws_params,
    draws_physical,
    interval95,
    posterior_bands,
    tis_band,
)
from brdf_infer.posterior._likelihood import ModelData, build_model_data
from brdf_infer.posterior._loo import (
    ExactTerm,
    LeaveOneOut,
    elpd_difference,
    psis_loo,
    rank_models,
    relative_efficiency,
)
from brdf_infer.posterior._loo_refit import (
    LEFT_OUT_SIGMA,
    exact_loo,
    exact_loo_rows,
)
from brdf_infer.posterior._model import LINEAR, NOISE_SITES, PosteriorModel, build_posterior_model
from brdf_infer.posterior._model_check import posterior_checks
from brdf_infer.posterior._nuts import (
    Cancelled,
    NutsProgram,
    chain_keys,
    programs_by_structure,
    stack_data,
)
from brdf_infer.posterior._padding import pad_datasets, paddable, padded_signature, row_count
from brdf_infer.posterior._potential import FlatPotential
from brdf_infer.posterior._power_scaling import power_scaling
from brdf_infer.posterior._prior import prior_draws
from brdf_infer.posterior._results import (
    THRESHOLDS,
    family_draws,
    flatten_draws,
    load_run_family,
    loo_terms,
    run_measurements,
)
from brdf_infer.posterior._run import (
    CHECKPOINT_FILE,
    PosteriorRun,
    build_model,
    complete_run,
    model_name,
    posterior_settings,
    run_fingerprint,
    run_posterior,
    run_scene,
)
from brdf_infer.posterior._samplers import (
    Draws,
    Refused,
    nuts_draws,
    program_draws,
    run_emcee,
    run_nuts,
)
from brdf_infer.posterior._targets import (
    NEW_PART_EFFECT,
    QUESTIONS,
    SAMPLE_EFFECT,
    chosen_target,
    latent_effect_draws,
    load_run_target,
    target_log_factor,
)

__all__ = [
    "CHECKPOINT_FILE",
    "FAMILY_TIS_DRAWS",
    "LEFT_OUT_SIGMA",
    "LINEAR",
    "NEW_PART_EFFECT",
    "NOISE_SITES",
    "QUANTILES",
    "QUESTIONS",
    "SAMPLE_EFFECT",
    "THRESHOLDS",
    "Cancelled",
    "Draws",
    "ExactTerm",
    "FlatPotential",
    "LeaveOneOut",
    "ModelData",
    "NutsProgram",
    "PosteriorModel",
    "PosteriorRun",
    "Refused",
    "build_model",
    "build_model_data",
    "build_posterior_model",
    "chain_keys",
    "chosen_target",
    "complete_run",
    "draws_params",
    "draws_physical",
    "elpd_difference",
    "exact_loo",
    "exact_loo_rows",
    "family_draws",
    "flatten_draws",
    "interval95",
    "latent_effect_draws",
    "load_run_family",
    "load_run_target",
    "loo_terms",
    "model_name",
    "nuts_draws",
    "pad_datasets",
    "paddable",
    "padded_signature",
    "posterior_bands",
    "posterior_checks",
    "posterior_settings",
    "power_scaling",
    "prior_draws",
    "program_draws",
    "programs_by_structure",
    "psis_loo",
    "rank_models",
    "relative_efficiency",
    "row_count",
    "run_emcee",
    "run_fingerprint",
    "run_measurements",
    "run_nuts",
    "run_posterior",
    "run_scene",
    "stack_data",
    "target_log_factor",
    "tis_band",
]
