"""NUTS (NumPyro) and emcee over the one log-density of a :class:`PosteriorModel`.

Both return :class:`Draws`: every model site (sampled and deterministic) as arrays of shape
(chain, draw, ...), sampler statistics, and timings. emcee samples NumPyro's potential
function on the unconstrained space, jitted and vmapped over walkers (``vectorize=True``),
so the two samplers differ only by how they sample.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import signal
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer._internal.atomic import atomic_write_bytes
from brdf_infer.errors import BadInputError
from brdf_infer.posterior._compile_clock import compile_clock
from brdf_infer.posterior._model import PosteriorModel
from brdf_infer.posterior._nuts import NutsOutput, NutsProgram, chain_keys
from brdf_infer.posterior._potential import FlatPotential


class Refused(NamedTuple):
    """A sampler's refusal to draw (Laplace + PSIS whose mode search or Pareto k̂ fails, an
    importance refit outside the run's space): ``reason``, one line, for the caller's
    fallback."""

    reason: str


@dataclass(frozen=True)
class Draws:
    """Posterior draws of one run.

    Attributes:
        sites: every sampled and deterministic site, shape (chain, draw, ...).
        stats: sampler statistics (``diverging``, ``energy``, ``lp``, ...), shape (chain, draw).
        sampler: ``nuts``, ``laplace`` or ``emcee``.
        settings: the sampler's settings.
        seconds: wall time [s] of "sampling" (every iteration: NUTS warmup and draws, emcee
            burn-in and steps), of the emcee MAP search ("initialise"), and the JAX "compile"
            time, which the others exclude.
        extra: sampler-specific results (emcee: autocorrelation times, acceptance).
        program: the NUTS or Laplace program that drew them (None for emcee): a variant of the
            model that differs in data only samples through it, its programs already compiled.
        unconstrained: the draws on the flat unconstrained space, (chain, draw, dimension)
            (NUTS and Laplace runs), from which a variant's refit starts
            (:func:`brdf_infer.posterior._laplace.importance_refit`).
    """

    sites: dict[str, np.ndarray]
    stats: dict[str, np.ndarray]
    sampler: str
    settings: dict
    seconds: dict[str, float]
    extra: dict = field(default_factory=dict)
    program: Any = field(default=None, repr=False, compare=False)  # NutsProgram, LaplaceProgram
    unconstrained: np.ndarray | None = field(default=None, repr=False, compare=False)


def _progress_enabled(progress: bool | None) -> bool:
    return sys.stderr.isatty() if progress is None else progress


def run_nuts(
    model: PosteriorModel,
    *,
    chains: int = 4,
    warmup: int = 1000,
    draws: int = 1000,
    seed: int = 0,
    target_accept: float = 0.8,
    progress: bool | None = None,
    program: NutsProgram | None = None,
) -> Draws:
    """NUTS with a dense mass matrix (:class:`brdf_infer.posterior._nuts.NutsProgram`): the
    chains run through one compiled program, that of ``program`` where it serves ``model``
    with these settings (:meth:`~brdf_infer.posterior._nuts.NutsProgram.serves`)."""
    if program is None or not program.serves(model, warmup, target_accept):
        program = NutsProgram(model, warmup=warmup, target_accept=target_accept)
    output = program.run(
        model.data, chain_keys(seed, 1, chains)[0], draws, progress=_progress_enabled(progress)
    )
    return program_draws(program, output, chains=chains, draws=draws, seed=seed)


def program_draws(
    program: NutsProgram, output: NutsOutput, *, chains: int, draws: int, seed: int
) -> Draws:
    """:class:`Draws` of one data set's run through ``program`` (``chains`` × ``draws`` from
    :func:`chain_keys` of ``seed``), with the program and the unconstrained draws a refit
    starts from (:func:`brdf_infer.posterior._refit.refit`)."""
    settings = {
        "chains": chains,
        "warmup": program.warmup,
        "draws": draws,
        "seed": seed,
        "dense_mass": True,
        "target_accept": program.target_accept,
    }
    result = nuts_draws(output.sites, output.stats, settings, output.seconds)
    return dataclasses.replace(result, program=program, unconstrained=output.unconstrained)


def nuts_draws(sites: dict, stats: dict, settings: dict, seconds: dict[str, float]) -> Draws:
    """:class:`Draws` of one data set's NUTS output (sites and statistics (chain, draw, ...))."""
    return Draws(
        sites=sites,
        stats={
            "diverging": stats["diverging"],
            "energy": stats["energy"],
            "lp": -stats["potential_energy"],
            "acceptance_rate": stats["accept_prob"],
            "n_steps": stats["num_steps"],
            "tree_depth": np.log2(stats["num_steps"] + 1).astype(int),
        },
        sampler="nuts",
        settings=settings,
        seconds=seconds,
    )


class _LogDensity:
    """The model's log density on the flat unconstrained space, jitted and vmapped over
    walkers."""

    def __init__(self, model: PosteriorModel, seed: int):
        self.flat = FlatPotential(model)
        self.ndim = self.flat.dimension
        data = model.data
        self.postprocess = jax.jit(jax.vmap(lambda x: self.flat.constrain(x, data)))
        self._potential = lambda x: self.flat.potential(x, data)
        self._batched = jax.jit(jax.vmap(lambda x: -self._potential(x)))
        self._init_key = jax.random.PRNGKey(seed + 1)
        self._data = data

    def __call__(self, positions: np.ndarray) -> np.ndarray:
        values = np.asarray(self._batched(jnp.asarray(positions)))
        return np.where(np.isfinite(values), values, -np.inf)

    def maximum_a_posteriori(self, starts: int = 8) -> np.ndarray:
        """The MAP on the unconstrained space: BFGS from ``starts`` dispersed points, vmapped."""
        keys = jax.random.split(self._init_key, starts)
        flat, data = self.flat, self._data

        def minimise(key):
            value, potential, _ = flat.search(key, data, 1e-9, 5000)
            return value, potential

        values, potentials = jax.jit(jax.vmap(minimise))(keys)
        potentials = jnp.where(jnp.isfinite(potentials), potentials, jnp.inf)
        return np.asarray(values[jnp.argmin(potentials)])

    def initial_positions(self, walkers: int, seed: int) -> np.ndarray:
        """Walkers in a small Gaussian ball (1e-3 in unconstrained units) around the MAP."""
        centre = self.maximum_a_posteriori()
        rng = np.random.default_rng(seed)
        return centre + 1e-3 * rng.standard_normal((walkers, centre.size))


@contextlib.contextmanager
def _deferred_interrupts():
    """Within the block, SIGINT and SIGTERM only set a flag (read with the yielded function).

    emcee prints a traceback when its log-probability raises, so the interrupt is taken between
    checkpointed chunks instead. Outside the main thread nothing is changed.
    """
    received: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield lambda: False
        return
    previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    for sig in previous:
        signal.signal(sig, lambda signum, frame: received.append(signum))
    try:
        yield lambda: bool(received)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def emcee_settings(dimension: int, walkers: int | None, steps: int, burn: int, seed: int) -> dict:
    """The checked settings of an emcee run (``walkers`` default: max(24, 2 × dimension)).

    Raises:
        BadInputError: fewer than 2 × dimension walkers, or ``burn`` ≥ ``steps``.
    """
    walkers = max(24, 2 * dimension) if walkers is None else walkers
    if walkers < 2 * dimension:
        raise BadInputError(
            f"emcee needs at least {2 * dimension} walkers, got {walkers}", field="walkers"
        )
    if not 0 <= burn < steps:
        raise BadInputError(
            f"burn-in ({burn}) must be below the number of steps ({steps})", field="warmup"
        )
    return {"walkers": walkers, "steps": steps, "burn": burn, "seed": seed}


def load_checkpoint(path: Path | None, settings: dict, identity: dict):
    """The checkpoint at ``path`` if this run (``settings``, ``identity``) wrote it.

    Raises:
        BadInputError: no checkpoint, or one that another run wrote (one line naming what
            differs).
    """
    if path is None or not path.exists():
        raise BadInputError("no checkpoint to resume from", file=path)
    try:
        saved = np.load(path)
    except (OSError, ValueError) as error:
        raise BadInputError(f"cannot read the checkpoint: {error}", file=path) from None
    _check_checkpoint(path, saved, settings, identity)
    return saved


def _check_checkpoint(path: Path, saved, settings: dict, identity: dict) -> None:
    """Refuse a checkpoint that another run wrote: one line naming everything that differs."""
    differences = []
    for key, value in identity.items():
        stored = f"identity_{key}"
        if stored not in saved.files or str(saved[stored]) != value:
            differences.append(key)
    for key, value in settings.items():
        if key not in saved.files or int(saved[key]) != value:
            differences.append(
                f"{key} ({int(saved[key]) if key in saved.files else '?'} there, {value} now)"
            )
    if differences:
        raise BadInputError(
            "the checkpoint was written by another run (differs in: "
            + ", ".join(differences)
            + "); start afresh without --resume or with another --out",
            file=path,
        )


def _save_checkpoint(path: Path, content: dict) -> None:
    buffer = io.BytesIO()
    np.savez(buffer, **content)
    atomic_write_bytes(path, buffer.getvalue())


def _random_state_arrays(state) -> dict:
    name, keys, position, has_gauss, cached = state
    return {
        "rng_name": np.array(name),
        "rng_keys": keys,
        "rng_pos": np.array(position),
        "rng_has_gauss": np.array(has_gauss),
        "rng_cached": np.array(cached),
    }


def _random_state_from(saved) -> tuple:
    return (
        str(saved["rng_name"]),
        saved["rng_keys"],
        int(saved["rng_pos"]),
        int(saved["rng_has_gauss"]),
        float(saved["rng_cached"]),
    )


def run_emcee(
    model: PosteriorModel,
    *,
    walkers: int | None = None,
    steps: int = 20000,
    burn: int = 4000,
    seed: int = 0,
    checkpoint: Path | None = None,
    resume: bool = False,
    checkpoint_every: int = 500,
    fingerprint: dict[str, str] | None = None,
    progress: bool | None = None,
) -> Draws:
    """emcee's affine-invariant ensemble on NumPyro's potential, checkpointed as it goes.

    ``walkers`` defaults to max(24, 2 × dimension). The walkers start in a small ball around
    the MAP (found with BFGS on the same potential); the first ``burn`` steps are discarded,
    and the rest is thinned by ⌈τ_max/2⌉ (τ the integrated autocorrelation time), which keeps
    nearly all of the effective sample size.

    Every ``checkpoint_every`` steps the chain so far and the full sampler state (walker
    positions, log densities, random state) are written atomically to ``checkpoint``; with
    ``resume`` a run continues from it and ends exactly where an uninterrupted run with the
    same seed ends.

    Raises:
        BadInputError: too few walkers, ``burn`` ≥ ``steps``, or a checkpoint that does not
            match the settings.
    """
    density = _LogDensity(model, seed)
    settings = emcee_settings(density.ndim, walkers, steps, burn, seed)
    walkers = settings["walkers"]
    identity = {**(fingerprint or {}), "dimension": str(density.ndim)}
    with compile_clock() as compile_seconds:
        initial = _emcee_start(
            density, settings, identity, seed, checkpoint, resume, compile_seconds
        )

    clock = time.perf_counter()
    accepted = _emcee_chunks(
        density, initial, settings, identity, steps, checkpoint, checkpoint_every, progress
    )
    sampling_seconds = time.perf_counter() - clock
    seconds = {
        "initialise": initial.initialise_seconds,
        "sampling": sampling_seconds,
        "compile": compile_seconds[0],
    }
    return _emcee_draws(density, initial, accepted, settings, seconds, steps, burn)


class _EmceeStart(NamedTuple):
    """Where an emcee run starts: its sampler state and the chain so far (resumed), or the
    walkers around the MAP."""

    state: Any
    chain_parts: list
    log_prob_parts: list
    accepted: np.ndarray
    done: int
    initialise_seconds: float


def _emcee_start(density, settings, identity, seed, checkpoint, resume, compile_seconds):
    """The run's start (:func:`run_emcee`): from ``checkpoint`` with ``resume``, else the
    walkers in a small ball around the MAP (its search timed, less ``compile_seconds``)."""
    import emcee  # imported when an emcee run needs it (not by NUTS runs)

    walkers = settings["walkers"]
    chain_parts, log_prob_parts, accepted, done = [], [], np.zeros(walkers), 0
    initialise_seconds = 0.0
    if resume:
        saved = load_checkpoint(checkpoint, settings, identity)
        done = int(saved["done"])
        chain_parts, log_prob_parts = [saved["chain"]], [saved["log_prob"]]
        accepted = saved["accepted"]
        state = emcee.State(
            saved["coords"],
            log_prob=saved["state_log_prob"],
            random_state=_random_state_from(saved),
        )
    else:
        clock = time.perf_counter()
        start = density.initial_positions(walkers, seed)
        state = emcee.State(
            start,
            log_prob=density(start),
            random_state=np.random.RandomState(seed).get_state(),
        )
        initialise_seconds = time.perf_counter() - clock - compile_seconds[0]  # MAP search
    return _EmceeStart(state, chain_parts, log_prob_parts, accepted, done, initialise_seconds)


def _emcee_chunks(
    density, initial, settings, identity, steps, checkpoint, checkpoint_every, progress
):
    """Sample from ``initial`` to ``steps`` in chunks of ``checkpoint_every`` steps, each
    chunk's chain appended to ``initial``'s and checkpointed; the accepted counts."""
    import emcee  # imported when an emcee run needs it (not by NUTS runs)

    walkers = settings["walkers"]
    state, chain_parts, log_prob_parts = initial.state, initial.chain_parts, initial.log_prob_parts
    accepted, done = initial.accepted, initial.done
    bar = None
    if _progress_enabled(progress):
        from tqdm import tqdm

        bar = tqdm(total=steps, initial=done, desc="emcee", unit="step", file=sys.stderr)
    with _deferred_interrupts() as interrupted:
        while done < steps:
            if interrupted():
                raise KeyboardInterrupt
            chunk = min(checkpoint_every, steps - done)
            sampler = emcee.EnsembleSampler(walkers, density.ndim, density, vectorize=True)
            state = sampler.run_mcmc(state, chunk, progress=False)
            chain_parts.append(sampler.get_chain())
            log_prob_parts.append(sampler.get_log_prob())
            accepted = accepted + sampler.backend.accepted
            done += chunk
            if bar is not None:
                bar.update(chunk)
            if checkpoint is not None:
                _save_checkpoint(
                    checkpoint,
                    {
                        **{k: np.array(v) for k, v in settings.items()},
                        **{f"identity_{k}": np.array(v) for k, v in identity.items()},
                        "done": np.array(done),
                        "chain": np.concatenate(chain_parts),
                        "log_prob": np.concatenate(log_prob_parts),
                        "accepted": accepted,
                        "coords": state.coords,
                        "state_log_prob": state.log_prob,
                        **_random_state_arrays(state.random_state),
                    },
                )
    if bar is not None:
        bar.close()
    return accepted


def _emcee_draws(density, initial, accepted, settings, seconds, steps, burn) -> Draws:
    """The draws after ``burn``, thinned by ⌈τ_max/2⌉, the walkers as chains."""
    import emcee  # imported when an emcee run needs it (not by NUTS runs)

    walkers = settings["walkers"]
    chain_parts, log_prob_parts = initial.chain_parts, initial.log_prob_parts
    chain = np.concatenate(chain_parts)[burn:]  # (steps − burn, walkers, ndim)
    log_prob = np.concatenate(log_prob_parts)[burn:]
    tau = emcee.autocorr.integrated_time(chain, quiet=True)
    thin = max(1, int(np.ceil(np.max(tau) / 2)))  # keeps nearly every effective draw
    chain, log_prob = chain[::thin], log_prob[::thin]
    positions = np.swapaxes(chain, 0, 1)  # walkers as chains: (walkers, draws, ndim)
    flat = positions.reshape(-1, density.ndim)
    constrained = density.postprocess(jnp.asarray(flat))
    sites = {
        k: np.asarray(v).reshape(walkers, chain.shape[0], *np.shape(v)[1:])
        for k, v in constrained.items()
    }
    return Draws(
        sites=sites,
        stats={"lp": np.swapaxes(log_prob, 0, 1)},
        sampler="emcee",
        settings=settings,
        seconds=seconds,
        extra={
            "autocorrelation_time": tau,
            "steps_per_autocorrelation_time": float((steps - burn) / np.max(tau)),
            "acceptance_fraction": float(np.mean(accepted) / steps),
            "thin": thin,
        },
    )
