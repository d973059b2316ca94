"""NUTS over a :class:`PosteriorModel`: one compiled program for every chain and data set.

NumPyro's ``MCMC`` compiles its loop once per sequential chain and cannot give each chain
its own data set. Here NumPyro's functional NUTS (``numpyro.infer.hmc.hmc``, dense mass
matrix, dual-averaging step size, windowed warmup) is compiled once per model structure and
data shape, with the data as an argument: the chains of one scene, the replicates of
simulation-based calibration and a batch of scenes all run through the same compiled
program (on a CPU one data set per core, on an accelerator vmapped).

Chains start at the lowest-potential of 16 points drawn uniformly in [−2, 2] on the
unconstrained space (NumPyro's ``init_to_uniform`` range), so each chain starts dispersed but
away from numerically hopeless corners.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import os
import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from numpyro.infer.hmc import HMCState, hmc
from numpyro.infer.hmc_util import HMCAdaptState

from brdf_infer._internal.sharding import gather_batch, shard_batch
from brdf_infer._internal.stored_programs import (
    Unkeyable,
    canonical_bytes,
    compile_stored,
    register_tree_types,
)
from brdf_infer.model.error_model import NoiseLayout
from brdf_infer.posterior._compile_clock import compile_clock
from brdf_infer.posterior._likelihood import ModelData
from brdf_infer.posterior._model import PosteriorModel, model_identity
from brdf_infer.posterior._padding import pad_datasets
from brdf_infer.posterior._potential import FlatPotential
from brdf_infer.predict.observations import Observations

INIT_CANDIDATES = 16
# XLA's CPU backend (jaxlib 0.10) hands large fused loops to YNNPACK; when two threads run one
# such program at once its pooled executables keep memory: 18-40 MB/s while two chains of a
# 19 637-row table sampled side by side, flat with this fusion off (tools/nuts_memory_growth.py;
# the gradient at 42 / 2e3 / 2e4 rows is the same within the machine's noise either way)
CPU_COMPILER_OPTIONS = {"xla_cpu_experimental_ynn_fusion_type": ""}
CHUNK = 50  # iterations per compiled call: one program whatever the number of draws
CONSTRAIN_BLOCK = 250  # draws per call of the constraining program (NutsProgram._constrained)
_STATISTICS = ("diverging", "potential_energy", "energy", "accept_prob", "num_steps")
# the named tuples of the programs' arguments and results, which a stored program names
register_tree_types((HMCState, HMCAdaptState, ModelData, Observations, NoiseLayout))


@dataclass
class NutsOutput:
    """Draws of one or many data sets.

    Attributes:
        sites: every model site, shape (data sets, chains, draws, ...).
        stats: ``diverging``, ``potential_energy``, ``energy``, ``accept_prob``, ``num_steps``,
            shape (data sets, chains, draws).
        seconds: ``sampling`` (iterations, warmup included) and ``compile`` [s].
        unconstrained: the draws on the flat unconstrained space, (chains, draws, dimension)
            (one data set's run only; None for a batch).
    """

    sites: dict[str, np.ndarray]
    stats: dict[str, np.ndarray]
    seconds: dict[str, float]
    unconstrained: np.ndarray | None = None


class NutsProgram:
    """The compiled NUTS program of one model structure and one set of sampler settings.

    Args:
        model: the posterior model (its ``data`` fixes the shapes).
        warmup: warmup iterations per chain (step size and dense mass matrix adapted).
        target_accept: target acceptance probability of the step-size adaptation.
        max_tree_depth: largest NUTS tree depth.
        warmup_tree_depth: largest tree depth during the warmup (default ``max_tree_depth``).
            Early in the warmup the step size and mass matrix are still poor and a trajectory
            can run to 2^10 leapfrog steps; capping it there bounds the cost of adapting
            without touching the kept draws.
    """

    def __init__(
        self,
        model: PosteriorModel,
        *,
        warmup: int,
        target_accept: float = 0.8,
        max_tree_depth: int = 10,
        warmup_tree_depth: int | None = None,
    ):
        self.model = model
        self.flat = FlatPotential(model)
        self._init_kernel, self._sample_kernel = hmc(
            potential_fn_gen=self._potential_gen, algo="NUTS"
        )
        self.warmup = warmup
        self._kernel_options = {
            "num_warmup": warmup,
            "dense_mass": True,
            "target_accept_prob": target_accept,
            "max_tree_depth": (warmup_tree_depth or max_tree_depth, max_tree_depth),
        }
        self._compiled: dict = {}
        self._lock = threading.Lock()
        self._kernel_ready = False  # whether init_kernel ran (traced) in this process
        # the module constants the programs close over (a stored program's key holds them)
        self._constants = (INIT_CANDIDATES, CHUNK, CONSTRAIN_BLOCK)

    @property
    def target_accept(self) -> float:
        """The target acceptance probability of the step-size adaptation."""
        return self._kernel_options["target_accept_prob"]

    def serves(self, model: PosteriorModel, warmup: int, target_accept: float) -> bool:
        """Whether this program samples ``model`` under these settings too: the same model but
        for its data (the same family, priors, scene and error-model structure, the error
        model's data options aside; data of the same shapes), so a variant of a run's model
        whose options are data (e.g. zero angle-error scales) reuses the run's compiled
        programs."""
        return (
            warmup == self.warmup
            and target_accept == self.target_accept
            and same_structure(model, self.model)
        )

    # ---------------------------------------------------------------- one chain, one data set

    def _potential_gen(self, data: ModelData):
        return lambda z: self.flat.potential(z, data)

    def _start(self, key, data: ModelData):
        self._kernel_ready = True  # NumPyro's init_kernel sets what sample_kernel reads
        candidates_key, kernel_key = jax.random.split(key)
        start = self.flat.best_of_uniform(candidates_key, data, INIT_CANDIDATES)
        return self._init_kernel(
            start, **self._kernel_options, model_args=(data,), rng_key=kernel_key
        )

    def _steps(self, state, data: ModelData, length: int):
        if not self._kernel_ready:  # the start program was loaded, not traced: trace it here
            jax.eval_shape(self._start, jnp.zeros(2, jnp.uint32), data)

        def step(state, _):
            state = self._sample_kernel(state, model_args=(data,))
            record = (state.z, *(getattr(state, k) for k in _STATISTICS))
            return state, record

        return jax.lax.scan(step, state, None, length=length)

    # ---------------------------------------------------------------- compiled

    def _compile(self, name: str, function: Callable, *arguments, stored: bool = False):
        """``function`` compiled for ``arguments``, once per program; ``stored``: loaded without
        tracing where a run stored it (:mod:`brdf_infer._internal.stored_programs`, keyed on
        the model and the sampler's settings, what else ``function`` closes over). The
        vmapped programs of a batch are not stored: their arguments' shardings depend on the
        devices a run is given."""
        key = (name, *(jax.tree_util.tree_structure(a) for a in arguments), _shapes(arguments))
        with self._lock:
            if key not in self._compiled:
                self._compiled[key] = (
                    self._stored(name, function, arguments)
                    if stored
                    else jax.jit(function).lower(*arguments).compile(_compiler_options())
                )
            return self._compiled[key]

    def _stored(self, name: str, function: Callable, arguments: tuple):
        try:
            identity = canonical_bytes(
                (name, model_identity(self.model), self._kernel_options, self._constants)
            )
        except Unkeyable:  # a scene value without a faithful text: traced every run
            return jax.jit(function).lower(*arguments).compile(_compiler_options())
        return compile_stored(
            function, arguments, identity=identity, compiler_options=_compiler_options()
        )

    def _chain(self, key, data: ModelData, total: int, on_chunk=None, cancel=None) -> list:
        """One chain of ``total`` iterations in chunks of :data:`CHUNK` (the last one's surplus
        is dropped): records (iterations, ...). Stops between chunks once ``cancel`` is set."""
        chunk = CHUNK
        state = self._compile("start", self._start, key, data, stored=True)(key, data)
        steps = self._compile(
            "steps", lambda s, d: self._steps(s, d, chunk), state, data, stored=True
        )
        parts, done = [], 0
        while done < total:
            if cancel is not None and cancel.is_set():
                raise Cancelled
            state, record = steps(state, data)
            parts.append(jax.device_get(record))
            if on_chunk is not None:
                on_chunk(min(chunk, total - done))
            done += chunk
        return [np.concatenate([p[k] for p in parts])[:total] for k in range(len(parts[0]))]

    def _single(
        self, data, keys, draws: int, on_chunk=None, workers: int = 1, cancel=None
    ) -> NutsOutput:
        """All chains of one data set, ``workers`` side by side; arrays (chains, draws, ...).

        Each chain runs the same compiled program with its own key, so its draws do not
        depend on how many run at once.
        """
        total = self.warmup + draws
        records = _side_by_side(
            lambda key, stop: self._chain(key, data, total, on_chunk, stop),
            list(keys),
            workers,
            cancel,
        )
        flat_z, *statistics = (
            np.stack([r[k] for r in records])[:, self.warmup :] for k in range(len(records[0]))
        )
        return NutsOutput(
            sites=self._constrained(flat_z, data),
            stats=dict(zip(_STATISTICS, statistics, strict=True)),
            seconds={},
            unconstrained=flat_z,
        )

    def _constrained(self, flat_z: np.ndarray, data: ModelData) -> dict[str, np.ndarray]:
        """Every site of the draws ``flat_z`` (chains, draws, dimension), through one program
        of :data:`CONSTRAIN_BLOCK` draws whatever their number (a refit's fewer draws reuse
        the run's program instead of tracing their own)."""
        shape = flat_z.shape[:-1]
        rows = flat_z.reshape(-1, flat_z.shape[-1])
        count = len(rows)
        padded = np.concatenate([rows, np.repeat(rows[-1:], -count % CONSTRAIN_BLOCK, axis=0)])
        constrain = jax.vmap(self.flat.constrain, (0, None))
        block = jnp.asarray(padded[:CONSTRAIN_BLOCK])
        program = self._compile("constrain", constrain, block, data, stored=True)
        parts = [
            jax.device_get(program(jnp.asarray(padded[k : k + CONSTRAIN_BLOCK]), data))
            for k in range(0, len(padded), CONSTRAIN_BLOCK)
        ]
        return {
            k: np.concatenate([p[k] for p in parts])[:count].reshape(*shape, *np.shape(v)[1:])
            for k, v in parts[0].items()
        }

    def run(
        self,
        data: ModelData,
        keys: jnp.ndarray,
        draws: int,
        *,
        workers: int | None = None,
        cancel: threading.Event | None = None,
        progress: bool = False,
        description: str = "NUTS",
    ) -> NutsOutput:
        """Every chain of one data set through one compiled program, side by side in threads.

        The chains share the compiled program and each has its own key, so the draws are
        those of running them one after another (the same program, bit for bit), in about
        1/workers of the time on a CPU with that many cores. A small model's NUTS step is
        latency-bound (a few µs of arithmetic per gradient), so threads over one program beat
        vmapped chains, which wait for the longest trajectory of every iteration.

        Args:
            data: the data set.
            keys: PRNG keys, one per chain (chains, 2).
            draws: kept draws per chain (after the warmup).
            workers: chains at once (default: one per core, at most one per chain).
            cancel: set it (from another thread or a signal handler) to stop the chains
                between compiled chunks; :class:`Cancelled` is raised.
            progress: a progress bar on stderr.
            description: the progress bar's label.

        Returns:
            Draws of shape (chains, draws, ...).
        """
        total = self.warmup + draws
        workers = default_workers(len(keys)) if workers is None else workers
        bar = _progress_bar(progress, len(keys) * total, description)
        with compile_clock() as compile_seconds:
            clock = time.perf_counter()
            try:
                output = self._single(
                    data, keys, draws, None if bar is None else bar.update, workers, cancel
                )
            finally:
                if bar is not None:
                    bar.close()
            seconds = time.perf_counter() - clock
        output.seconds = {
            "sampling": max(seconds - compile_seconds[0], 0.0),
            "compile": compile_seconds[0],
        }
        return output

    def run_many(
        self,
        datasets: ModelData,
        keys: jnp.ndarray,
        draws: int,
        *,
        workers: int | None = None,
        mode: str = "auto",
        cancel: threading.Event | None = None,
        progress: bool = False,
        description: str = "NUTS",
        devices: list | None = None,
    ) -> NutsOutput:
        """Every chain of many data sets of one shape with the same compiled program.

        On a CPU the data sets are spread over ``workers`` threads (default: one per core),
        each running the one-data-set program: measured on the bundled scene, a vmapped batch
        of 50 data sets costs 4× more per data set than this on a 2-core CPU, because every
        vmapped iteration waits for the longest NUTS trajectory among the data sets and small
        batched linear algebra is slow there. On an accelerator the data sets run vmapped.

        Args:
            datasets: data sets stacked on a leading axis (:func:`stack_data`).
            keys: PRNG keys of shape (data sets, chains, 2).
            draws: kept draws per chain.
            workers: threads on a CPU (default ``os.cpu_count()``).
            mode: ``threads`` (one data set per thread, each through the one-data-set
                program), ``vmap`` (one program vmapped over the data sets, the data-set
                axis sharded over every device JAX sees: :func:`shard_batch`) or ``auto``:
                threads on a single CPU device, else vmap.
            cancel: set it to stop between compiled chunks (threads mode) or before the
                vmapped program starts; :class:`Cancelled` is raised.
            progress: a progress bar (per data set) on stderr.
            description: the progress bar's label.
            devices: the devices of ``vmap`` mode and of ``auto``'s choice (default every
                device JAX sees, those of other processes included; ``jax.local_devices()``
                for a process that runs data sets of its own).

        Returns:
            Draws of shape (data sets, chains, draws, ...).
        """
        if mode not in ("auto", "threads", "vmap"):
            raise ValueError(f"unknown mode {mode!r} (auto, threads, vmap)")
        if mode == "auto":
            count = jax.device_count() if devices is None else len(devices)
            single_cpu = jax.default_backend() == "cpu" and count == 1
            mode = "threads" if single_cpu else "vmap"
        count = int(keys.shape[0])
        total = self.warmup + draws
        bar = _progress_bar(progress, count, description, unit="data set")
        with compile_clock() as compile_seconds:
            clock = time.perf_counter()
            if mode == "threads":
                outputs = self._threaded(datasets, keys, draws, workers, bar, cancel)
            else:
                if cancel is not None and cancel.is_set():
                    raise Cancelled
                outputs = [self._vmapped(datasets, keys, draws, total, devices)]
                if bar is not None:
                    bar.update(count)
            seconds = time.perf_counter() - clock
        if bar is not None:
            bar.close()
        # threads: one output per data set, stacked on a new axis; vmap: one output that
        # already has the data-set axis (also for a single data set)
        stacked = mode == "threads"
        return NutsOutput(
            sites={k: np.stack([o.sites[k] for o in outputs]) for k in outputs[0].sites}
            if stacked
            else outputs[0].sites,
            stats={k: np.stack([o.stats[k] for o in outputs]) for k in outputs[0].stats}
            if stacked
            else outputs[0].stats,
            seconds={
                "sampling": max(seconds - compile_seconds[0], 0.0),
                "compile": compile_seconds[0],
            },
        )

    def _threaded(self, datasets, keys, draws, workers, bar, cancel) -> list[NutsOutput]:
        """One data set per thread, its chains one after another (the cores are busy)."""

        def one(index: int, stop: threading.Event) -> NutsOutput:
            data = jax.tree_util.tree_map(lambda leaf: leaf[index], datasets)
            output = self._single(data, keys[index], draws, cancel=stop)
            if bar is not None:
                bar.update(1)
            return output

        return _side_by_side(one, list(range(int(keys.shape[0]))), workers or 0, cancel)

    def _vmapped(self, datasets, keys, draws, total, devices=None) -> NutsOutput:
        count = int(keys.shape[0])
        datasets, keys = shard_batch((datasets, keys), devices)
        start = jax.vmap(jax.vmap(self._start, (0, None)), (0, 0))
        steps = jax.vmap(jax.vmap(lambda s, d: self._steps(s, d, total), (0, None)), (0, 0))
        state = self._compile("vstart", start, keys, datasets)(keys, datasets)
        _, records = self._compile("vsteps", steps, state, datasets)(state, datasets)
        flat_z = records[0][:, :, self.warmup :]
        statistics = [np.asarray(r)[:count, :, self.warmup :] for r in gather_batch(records[1:])]
        constrain = jax.vmap(jax.vmap(jax.vmap(self.flat.constrain, (0, None)), (0, None)))
        sites = self._compile("vconstrain", constrain, flat_z, datasets)(flat_z, datasets)
        return NutsOutput(
            sites={k: np.asarray(v)[:count] for k, v in gather_batch(sites).items()},
            stats=dict(zip(_STATISTICS, statistics, strict=True)),
            seconds={},
        )


class Cancelled(Exception):
    """Sampling stopped because its ``cancel`` event was set."""


def default_workers(tasks: int) -> int:
    """Threads for ``tasks`` independent chains or data sets: one per core, at most one per
    task."""
    return max(1, min(tasks, os.cpu_count() or 1))


class _Stop:
    """Set when this group of threads must stop: by itself, or by an outside ``cancel``."""

    def __init__(self, cancel: threading.Event | None):
        self._own = threading.Event()
        self._cancel = cancel

    def set(self) -> None:
        self._own.set()

    def is_set(self) -> bool:
        return self._own.is_set() or (self._cancel is not None and self._cancel.is_set())


def _side_by_side(function, items: list, workers: int, cancel=None) -> list:
    """``function(item, stop)`` for every item, ``workers`` at a time (0: one per core), in
    order. Compiled programs are built once under :meth:`NutsProgram._compile`'s lock, so the
    threads may start together. If one raises (or the caller is interrupted), ``stop`` is set
    so the others end at their next chunk, and the error propagates."""
    stop = _Stop(cancel)
    workers = workers or default_workers(len(items))
    if workers <= 1 or len(items) <= 1:
        return [function(item, stop) for item in items]
    with ThreadPoolExecutor(max_workers=workers) as pool:
        futures = [pool.submit(function, item, stop) for item in items]
        try:
            return [future.result() for future in futures]
        except BaseException:
            stop.set()
            raise


@functools.cache
def _compiler_options() -> dict | None:
    """:data:`CPU_COMPILER_OPTIONS` on a CPU whose XLA knows them (a jaxlib before the YNNPACK
    fusion, or one that dropped the experimental flag, refuses an unknown option: then none)."""
    if jax.default_backend() != "cpu" or not CPU_COMPILER_OPTIONS:
        return None
    try:
        jax.jit(lambda x: x + 1).lower(1.0).compile(CPU_COMPILER_OPTIONS)
    except Exception:  # XLA's "No such compile option" (JaxRuntimeError)
        return None
    return CPU_COMPILER_OPTIONS


def same_structure(model: PosteriorModel, mine: PosteriorModel) -> bool:
    """Whether ``model`` is ``mine`` but for its data (the same family, priors, scene and
    error-model structure, the error model's data options aside; data of the same shapes):
    a program compiled for one serves the other."""
    scene_fields = (f.name for f in dataclasses.fields(mine.scene) if f.name != "errors")
    return (
        model.family is mine.family
        and (model.whiten, model.sigma_scale, model.drop_log_jacobian)
        == (mine.whiten, mine.sigma_scale, mine.drop_log_jacobian)
        and all(getattr(model.scene, f) is getattr(mine.scene, f) for f in scene_fields)
        and model.errors.structure() == mine.errors.structure()
        and jax.tree_util.tree_structure(model.data) == jax.tree_util.tree_structure(mine.data)
        and _shapes(model.data) == _shapes(mine.data)
    )


def _shapes(arguments) -> tuple:
    return tuple(
        (tuple(np.shape(leaf)), str(jnp.asarray(leaf).dtype))
        for leaf in jax.tree_util.tree_leaves(arguments)
    )


def _progress_bar(enabled: bool, total: int, description: str, unit: str = "it"):
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=description, unit=unit, file=sys.stderr)


def stack_data(datasets: list[ModelData]) -> ModelData:
    """Data sets of one shape stacked on a new leading axis."""
    return jax.tree_util.tree_map(lambda *leaves: jnp.stack(leaves), *datasets)


def chain_keys(seed: int, datasets: int, chains: int) -> jnp.ndarray:
    """PRNG keys of shape (datasets, chains, 2) from one seed."""
    keys = jax.random.split(jax.random.PRNGKey(seed), datasets * chains)
    return keys.reshape(datasets, chains, *keys.shape[1:])


def programs_by_structure(
    models: list[PosteriorModel], **program_options
) -> list[tuple[NutsProgram, list[tuple[int, ModelData]]]]:
    """One NUTS program per error-model structure among ``models``, each with its members'
    data padded to one shape (:func:`brdf_infer.posterior._padding.pad_datasets`).

    Error-model options that are data of the compiled likelihood (calibration, rotation
    coupling, images per row) share a program; the others (``scene.errors.structure()``)
    compile their own. ``program_options`` go to :class:`NutsProgram`.

    Returns:
        (program, [(index into ``models``, padded data), ...]) per structure, in the order of
        each structure's first model.
    """
    groups: dict[str, list[int]] = {}
    for index, model in enumerate(models):
        key = json.dumps(model.scene.errors.structure(), sort_keys=True, default=str)
        groups.setdefault(key, []).append(index)
    programs = []
    for members in groups.values():
        datasets = pad_datasets([models[index].data for index in members])
        first = dataclasses.replace(models[members[0]], data=datasets[0])
        padded = list(zip(members, datasets, strict=True))
        programs.append((NutsProgram(first, **program_options), padded))
    return programs
