"""The settings records of the main job, the posterior and the studies: their defaults and
their checks, in one light module (no NumPyro, no ArviZ), so that the command line reads its
defaults from here and a notebook gets the same ones.

Every record checks its own fields when it is made and raises
:class:`~brdf_infer.errors.BadInputError` naming the field (``warmup``, ``target_accept``);
the command line names the option (``--warmup``, ``--target-accept``) when it prints it. The
home modules re-export their records (``brdf_infer.workflow.RunSettings``,
``brdf_infer.studies.sbc.SbcSettings``, ...).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from brdf_infer.errors import BadInputError
from brdf_infer.scene.design_target import DESIGN_BUDGET

if TYPE_CHECKING:
    from brdf_infer.scene import Studies

LSQ_STARTS = 16  # least-squares starts of a fit
NUTS_WARMUP = 1000  # NUTS warmup iterations per chain of a posterior run
EMCEE_BURN_IN = 4000  # emcee burn-in steps of a posterior run
SAMPLERS: tuple[str, ...] = ("auto", "nuts", "laplace", "emcee")
LAPLACE_MIN_ROWS = 1000  # "auto" samples tables of this many rows by Laplace + PSIS
BATCH_MODES: tuple[str, ...] = ("auto", "threads", "vmap")
PLANTED_FAULTS: dict[str, str] = {  # planted in the inference only; the simulations keep none
    "jacobian": "the whitening's log-Jacobian dropped from the inference's density",
    "prior": "every free parameter's prior moved by one prior sd in the inference",
}


def at_least(value: int, low: int, field: str) -> None:
    """Raises BadInputError naming ``field`` when ``value`` < ``low``."""
    if value < low:
        raise BadInputError(f"must be at least {low}, got {value}", field=field)


def check_family_name(name: str | None, field: str = "model") -> None:
    """Raises BadInputError naming ``field`` when ``name`` is not a model family (None: the
    scene's, always known)."""
    if name is not None:
        from brdf_infer.model import check_family_name as check

        check(name, field=field)


def check_nuts(chains: int, draws: int, warmup: int, target_accept: float) -> None:
    """The checks every NUTS setting shares: chains and draws at least 1, a warmup >= 0 and a
    target acceptance in (0, 1).

    Raises:
        BadInputError: naming the first field out of range.
    """
    at_least(chains, 1, "chains")
    at_least(draws, 1, "draws")
    if warmup < 0:
        raise BadInputError(f"must be >= 0, got {warmup}", field="warmup")
    if not 0 < target_accept < 1:
        raise BadInputError(f"must lie in (0, 1), got {target_accept}", field="target_accept")


@dataclass(frozen=True)
class RunSettings:
    """NUTS settings of the main job, the least-squares starts, the model family (None: the
    scene's ``[model] family``; :data:`AUTO_MODEL`: the family PSIS-LOO ranks first among
    :data:`AUTO_FAMILIES`), the studies (None: the scene's ``[studies]``) and ``force``: go on
    past failed plausibility checks (the verdict then names them)."""

    chains: int = 4
    draws: int = 1000
    warmup: int = NUTS_WARMUP
    seed: int = 0
    lsq_starts: int = LSQ_STARTS
    model: str | None = None
    studies: Studies | None = None
    force: bool = False

    def __post_init__(self) -> None:
        for name in ("chains", "draws", "lsq_starts"):
            at_least(getattr(self, name), 1, name)
        if self.warmup < 0:
            raise BadInputError(f"must be >= 0, got {self.warmup}", field="warmup")
        if self.model != AUTO_MODEL:
            check_family_name(self.model)


AUTO_MODEL = "auto"  # RunSettings.model: the family the comparison ranks first
AUTO_FAMILIES = ("strumik2024", "abg", "lambertian", "lambertian+abg")


def resolved_sampler(sampler: str, rows: int) -> str:
    """The sampler a run of ``rows`` rows starts with: ``auto`` resolved by
    :data:`LAPLACE_MIN_ROWS`, any other as it is."""
    if sampler != "auto":
        return sampler
    return "laplace" if rows >= LAPLACE_MIN_ROWS else "nuts"


@dataclass(frozen=True)
class PosteriorSettings:
    """How a posterior is sampled (:func:`brdf_infer.posterior.run_posterior`).

    Attributes:
        sampler: ``nuts``, ``laplace`` (Laplace's approximation corrected by Pareto-smoothed
            importance sampling, NUTS where its diagnostics refuse it), ``emcee``, or ``auto``
            (the default: ``laplace`` from :data:`LAPLACE_MIN_ROWS` rows, ``nuts`` below).
        chains, draws: NUTS chains and draws per chain (Laplace: chains × draws proposals,
            resampled into as many draws).
        warmup: NUTS warmup per chain, or emcee's burn-in in steps (None: :data:`NUTS_WARMUP`
            or :data:`EMCEE_BURN_IN`, by sampler).
        walkers, steps: emcee walkers (None: max(24, 2 × dimension)) and steps.
        seed: random seed of the sampler.
        target_accept: NUTS target acceptance probability.
    """

    sampler: str = "auto"
    chains: int = 4
    draws: int = 1000
    warmup: int | None = None
    walkers: int | None = None
    steps: int = 20000
    seed: int = 0
    target_accept: float = 0.8

    def __post_init__(self) -> None:
        if self.sampler not in SAMPLERS:
            raise BadInputError(
                f"unknown sampler {self.sampler!r} ({', '.join(SAMPLERS)})", field="sampler"
            )
        if self.warmup is None:
            default = EMCEE_BURN_IN if self.sampler == "emcee" else NUTS_WARMUP
            object.__setattr__(self, "warmup", default)
        check_nuts(self.chains, self.draws, self.warmup, self.target_accept)
        if self.walkers is not None:
            at_least(self.walkers, 1, "walkers")
        at_least(self.steps, 1, "steps")


@dataclass(frozen=True)
class BatchSettings:
    """NUTS settings shared by every scene of a batch (``seed``: each scene's chains get the
    keys ``posterior --seed`` gives them; ``mode``: one of :data:`BATCH_MODES`; ``force``: run
    scenes that fail a plausibility check)."""

    chains: int = 4
    draws: int = 1000
    warmup: int = NUTS_WARMUP
    seed: int = 0
    target_accept: float = 0.8
    mode: str = "auto"
    force: bool = False

    def __post_init__(self) -> None:
        check_nuts(self.chains, self.draws, self.warmup, self.target_accept)
        if self.mode not in BATCH_MODES:
            raise BadInputError(
                f"unknown mode {self.mode!r} ({', '.join(BATCH_MODES)})", field="mode"
            )


@dataclass(frozen=True)
class CompareSettings:
    """How each family of a PSIS-LOO comparison is sampled (NUTS; a warmup of at least 1;
    ``refit``: compute the leave-one-out term of a row with Pareto k above its limit
    (:func:`~brdf_infer.verdict.pareto_k_limit`) exactly)."""

    chains: int = 4
    warmup: int = 500
    draws: int = 1000
    seed: int = 0
    target_accept: float = 0.9
    refit: bool = True

    def __post_init__(self) -> None:
        check_nuts(self.chains, self.draws, self.warmup, self.target_accept)
        at_least(self.warmup, 1, "warmup")


@dataclass(frozen=True)
class SensitivitySettings:
    """How every variant of the sensitivity study is sampled (NUTS, the same settings and
    seed for all).

    The defaults keep the study at a few minutes on 2 cores: 4 × 500 draws give the 95 %
    intervals of TIS and π·BRDF0 to a few tenths of a per cent and PSIS-LOO its usual
    precision. ``refit``: compute the leave-one-out term of a row with Pareto k above its limit
    (:func:`~brdf_infer.verdict.pareto_k_limit`) exactly,
    by one more posterior without it.
    """

    chains: int = 4
    warmup: int = 500
    draws: int = 500
    seed: int = 0
    target_accept: float = 0.8
    refit: bool = True

    def __post_init__(self) -> None:
        check_nuts(self.chains, self.draws, self.warmup, self.target_accept)


@dataclass(frozen=True)
class SbcSettings:
    """How SBC runs.

    Attributes:
        replicates: simulated data sets N.
        draws: posterior draws L the truth is ranked among (after thinning).
        thin: keep every ``thin``-th NUTS draw (draws × thin iterations after the warmup).
        warmup: NUTS warmup iterations per replicate.
        seed: seed of the simulations and of the sampler.
        sigma_scale: multiply the likelihood's σ by this in the inference only (1: no fault).
        planted_fault: a fault planted in the inference only (a key of
            :data:`PLANTED_FAULTS`; None: none), for ``strumik2024``.
        target_accept: NUTS target acceptance probability.
        warmup_tree_depth: largest NUTS tree depth during the warmup (10 after it). Without
            the cap, the first warmup iterations of a replicate whose prior draw sits far from
            the start run trees of up to 1023 leapfrog steps, and the warmup costs 3–20× the
            kept draws (measured on the bundled scene: 5,000–45,000 warmup steps against
            ≈ 2,000 after it); with depth 6 it is ≈ 7,000–10,000. The ranks are the check
            that the adaptation is still good enough.
    """

    replicates: int = 200
    draws: int = 100
    thin: int = 2
    warmup: int = 300
    seed: int = 0
    sigma_scale: float = 1.0
    target_accept: float = 0.8
    warmup_tree_depth: int = 6
    planted_fault: str | None = None

    def __post_init__(self) -> None:
        for name in ("replicates", "draws", "thin", "warmup"):
            at_least(getattr(self, name), 1, name)
        if not self.sigma_scale > 0:
            raise BadInputError(f"must be > 0, got {self.sigma_scale}", field="sigma_scale")
        if not 0 < self.target_accept < 1:
            raise BadInputError(
                f"must lie in (0, 1), got {self.target_accept}", field="target_accept"
            )
        if not 1 <= self.warmup_tree_depth <= 10:
            raise BadInputError(
                f"must be 1 … 10, got {self.warmup_tree_depth}", field="warmup_tree_depth"
            )
        check_planted_fault_name(self.planted_fault)


def check_planted_fault_name(fault: str | None) -> None:
    """Raises BadInputError (field ``planted_fault``) for a fault not in
    :data:`PLANTED_FAULTS` (None: no fault)."""
    if fault is not None and fault not in PLANTED_FAULTS:
        raise BadInputError(
            f"unknown planted fault {fault!r} (known: {', '.join(PLANTED_FAULTS)})",
            field="planted_fault",
        )


@dataclass(frozen=True)
class DesignOptions:
    """How ``design`` estimates the expected posterior sd after new rows.

    Attributes:
        draws: posterior draws used (evenly thinned from the run) [-], 50 … 100000.
        simulations: simulated outcomes J per candidate set [-], 8 … 4096.
        budget: rows chosen together (K), 1 … 10.
        seed: random seed of the simulated outcomes.
    """

    draws: int = 1000
    simulations: int = 128
    budget: int = DESIGN_BUDGET
    seed: int = 0

    def __post_init__(self) -> None:
        for name, low, high in (("draws", 50, 100000), ("simulations", 8, 4096), ("budget", 1, 10)):
            value = getattr(self, name)
            if not low <= value <= high:
                raise BadInputError(f"expected {low}..{high}, got {value}", field=name)
