"""Concurrency stress paths, each run in a child process under a watchdog.

jaxlib 0.10.2's CPU LAPACK handlers (``lapack_dpotrf_ffi``, ``lapack_dtrsm_ffi``) split a batch
over XLA's intra-op thread pool and block until the pieces are done
(``jax::ParallelBatchMap`` → ``absl::BlockingCounter::Wait``). When such a handler itself runs
on a pool thread (it does, right after a kernel that XLA split over the pool) and two programs
execute at once, every pool thread (two on a 2-core machine) can end up waiting for pieces
queued behind itself: the process deadlocks, idle, and SIGTERM does not end it. The paths here
run what the package runs concurrently (``batch`` in threads and vmap mode, ``posterior``, two
threads evaluating one compiled posterior program, and four processes compiling into one fresh
persistent compilation cache) in a child process each, so a deadlock is a timeout that is
reported, never a hung test suite or benchmark.

:func:`stress_rows` runs every path ``repeats`` times for the benchmark report;
``tests/test_concurrency.py`` runs each path ``BRDF_INFER_STRESS_REPEATS`` times (default 1).
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

REPEATS_VARIABLE = "BRDF_INFER_STRESS_REPEATS"
HEADERS = ["path", "repetitions", "hangs", "failures", "seconds per repetition"]

# The child registers faulthandler on SIGUSR1 so that a watchdog can read every thread's Python
# stack before killing it; everything else runs as ``python -m brdf_infer`` would.
_BOOTSTRAP = (
    "import faulthandler, runpy, signal, sys; "
    "faulthandler.register(signal.SIGUSR1, all_threads=True); "
    "sys.argv[0] = 'brdf_infer'; "
    "runpy.run_module('brdf_infer', run_name='__main__', alter_sys=True)"
)

# Two threads evaluating the posterior's compiled, vmapped constraining map and potential many
# times: the pattern of the deadlock without NUTS around it (each call is one execution of a
# program holding batched Cholesky factorisations and triangular solves).
POTENTIAL_SCRIPT = textwrap.dedent(
    """
    import faulthandler, signal, sys, threading
    faulthandler.register(signal.SIGUSR1, all_threads=True)
    import jax, jax.numpy as jnp
    import brdf_infer
    from brdf_infer._internal.cache import enable_compilation_cache
    from brdf_infer.posterior import build_posterior_model
    from brdf_infer.posterior._potential import FlatPotential
    from brdf_infer.scene import load_scene

    points, calls, threads = (int(a) for a in sys.argv[1:4])
    brdf_infer.use_float64(cache=False)
    enable_compilation_cache()
    scene = load_scene("lya")
    model = build_posterior_model(scene, scene.load_measurements())
    flat = FlatPotential(model)
    data = model.data
    # the shapes NutsProgram uses: (chains, draws, dimension), the data shared
    constrain = jax.jit(jax.vmap(jax.vmap(flat.constrain, (0, None)), (0, None)))
    potential = jax.jit(jax.vmap(jax.vmap(flat.potential, (0, None)), (0, None)))
    z = 0.5 * jax.random.normal(jax.random.PRNGKey(0), (2, points, flat.dimension))
    jax.block_until_ready((constrain(z, data), potential(z, data)))  # compile before threads
    done = []

    def work(seed):
        shifted = z + 0.01 * seed
        for _ in range(calls):
            jax.device_get(constrain(shifted, data))
            jax.device_get(potential(shifted, data))
        done.append(seed)

    workers = [threading.Thread(target=work, args=(k,), daemon=True) for k in range(threads)]
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    print("ok", len(done), "threads x", calls, "calls", flush=True)
    sys.exit(0 if len(done) == threads else 1)
    """
)

# Several processes started at once on one fresh compilation cache folder, each compiling
# and writing the same programs (JAX writes an entry in place, without a lock; a reader that
# finds one half-written cannot decompress it and compiles the program itself): every one must
# finish, with the same result. Prints the cache files and JAX's complaints about entries.
SHARED_CACHE_SCRIPT = textwrap.dedent(
    """
    import json, os, subprocess, sys, tempfile

    processes, command = int(sys.argv[1]), sys.argv[2:]
    cache = tempfile.mkdtemp(prefix="cache-", dir=".")  # fresh for every repetition
    env = dict(os.environ, BRDF_INFER_CACHE=cache)
    children = [
        subprocess.Popen(
            [sys.executable, "-m", "brdf_infer", *command],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
        )
        for _ in range(processes)
    ]
    done = [child.communicate() for child in children]

    def without_timings(value):
        if isinstance(value, dict):
            return {k: without_timings(v) for k, v in value.items() if "seconds" not in k}
        return [without_timings(v) for v in value] if isinstance(value, list) else value

    failed = [k for k, child in enumerate(children) if child.returncode != 0]
    for k in failed:
        print(f"process {k} exited with {children[k].returncode}:", done[k][1][-3000:])
    results = [json.loads(out) for out, _ in done] if not failed else []
    if results and any(without_timings(r) != without_timings(results[0]) for r in results):
        print("the processes disagree:", *(json.dumps(r)[:500] for r in results), sep="\\n")
        failed.append("results")
    complaints = sum(err.count("persistent compilation cache") for _, err in done)
    print(f"{processes} processes, {len(os.listdir(cache))} cache files, "
          f"{complaints} cache complaints, same results: {not failed}", flush=True)
    sys.exit(1 if failed else 0)
    """
)


@dataclass(frozen=True)
class Watched:
    """One child process run under the watchdog.

    Attributes:
        label: what ran.
        returncode: the exit status, None when the watchdog killed it (a hang).
        seconds: wall time [s].
        output: its stdout and stderr (interleaved), with the stacks the watchdog read when it
            timed out.
    """

    label: str
    returncode: int | None
    seconds: float
    output: str

    @property
    def hung(self) -> bool:
        return self.returncode is None

    @property
    def ok(self) -> bool:
        return self.returncode == 0

    def describe(self, tail: int = 12000) -> str:
        """A failure message: what happened, then the end of the output."""
        state = (
            f"HUNG: killed by the watchdog after {self.seconds:.0f} s"
            if self.hung
            else f"exited with status {self.returncode} after {self.seconds:.1f} s"
        )
        text = self.output if len(self.output) <= tail else "…" + self.output[-tail:]
        return f"{self.label}: {state}\n----- output -----\n{text}"


def _native_stacks(pid: int) -> str:
    """Every thread's native stack: gdb's (XLA's pool threads included, one line per frame,
    function names only) where gdb is installed, else ``py-spy dump --native``'s (Python
    threads only), else a note."""
    gdb = shutil.which("gdb")
    if gdb:
        try:
            done = subprocess.run(
                [gdb, "-p", str(pid), "-batch", "-nx", "-ex", "thread apply all bt 30"],
                capture_output=True,
                text=True,
                timeout=120,
            )
            return _compact_gdb(done.stdout) or done.stderr[-2000:]
        except (OSError, subprocess.SubprocessError) as error:
            return f"(gdb failed: {error})"
    spy = shutil.which("py-spy") or str(Path(sys.executable).with_name("py-spy"))
    if Path(spy).is_file():
        try:
            done = subprocess.run(
                [spy, "dump", "--native", "--pid", str(pid)],
                capture_output=True,
                text=True,
                timeout=60,
            )
            return done.stdout + done.stderr
        except (OSError, subprocess.SubprocessError) as error:
            return f"(py-spy failed: {error})"
    return "(neither gdb nor py-spy installed: no native stacks)"


def _compact_gdb(text: str) -> str:
    """gdb's ``thread apply all bt``, one line per frame (function name, 120 characters), the
    idle threads (only waiting in their pool's loop) left out."""
    threads, current = [], None
    for line in text.splitlines():
        if line.startswith("Thread "):
            current = [line.strip()]
            threads.append(current)
        elif current is not None and line.startswith("#"):
            match = re.match(r"#(\d+)\s+(?:0x[0-9a-f]+ in )?(\S+)", line)
            if match:
                current.append(f"  #{match.group(1)} {match.group(2)[:120]}")
    busy = [
        t
        for t in threads
        if any(k in "".join(t) for k in ("lapack", "ParallelBatchMap", "Execute", "PyEval"))
    ]
    busy.sort(key=lambda t: "ParallelBatchMap" not in "".join(t))  # the waits first
    return "\n".join("\n".join(t) for t in busy)


def run_watched(
    argv: Sequence[str],
    *,
    timeout: float,
    env: dict[str, str] | None = None,
    cwd: Path | str | None = None,
    label: str = "",
) -> Watched:
    """Run ``argv`` in its own process group; after ``timeout`` seconds read its stacks
    (Python ones through SIGUSR1 where the child registered faulthandler, native ones through
    py-spy where installed), kill the whole group and return it as hung. Never raises on a
    hang or a failure; never waits longer than ``timeout`` plus about a minute."""
    clock = time.perf_counter()
    process = subprocess.Popen(
        list(argv),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        stdin=subprocess.DEVNULL,
        text=True,
        errors="replace",
        env=env,
        cwd=cwd,
        start_new_session=True,
    )
    try:
        output, _ = process.communicate(timeout=timeout)
        return Watched(label, process.returncode, time.perf_counter() - clock, output)
    except subprocess.TimeoutExpired:
        seconds = time.perf_counter() - clock
        native = _native_stacks(process.pid)
        try:
            os.kill(process.pid, signal.SIGUSR1)  # faulthandler: Python stacks to stderr
            output, _ = process.communicate(timeout=5)
        except (subprocess.TimeoutExpired, ProcessLookupError):
            output = ""
        finally:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.pid, signal.SIGKILL)
        rest, _ = process.communicate()
        output = (output or "") + (rest or "")
        output += "\n----- native stacks at the timeout -----\n" + native
        return Watched(label, None, seconds, output)


def repeats_from_environment(default: int = 1) -> int:
    """``$BRDF_INFER_STRESS_REPEATS`` (at least 1), else ``default``."""
    value = os.environ.get(REPEATS_VARIABLE, "").strip()
    return max(1, int(value)) if value else default


# ---------------------------------------------------------------------------- the paths


@dataclass(frozen=True)
class StressSettings:
    """Sizes of the stress paths: small enough for a test, large enough that the compiled
    constraining map of ``chains × draws`` points is split over the thread pool (the deadlock
    needs that; a batch of a few dozen points runs on one thread)."""

    scenes: int = 4
    chains: int = 2
    draws: int = 1000
    warmup: int = 20
    points: int = 2000  # potential path: points per chain
    calls: int = 20  # potential path: calls per thread
    threads: int = 2  # potential path: Python threads
    processes: int = 4  # shared-cache path: processes on one fresh cache folder
    timeout: float = 150.0  # per repetition [s]: a cold repetition (compiling) takes 30–80 s


@dataclass
class StressPath:
    """One path: a name, and how to build its command in a work folder."""

    name: str
    command: Callable[[Path, StressSettings], tuple[list[str], dict[str, str]]]
    needs_scenes: bool = field(default=False)
    most_repeats: int | None = None  # a cap on the benchmark's repetitions (a costly path)


def child_environment(cache: Path, extra: dict[str, str] | None = None) -> dict[str, str]:
    """This process's environment with ``BRDF_INFER_CACHE=cache``, CPU JAX, and ``extra``
    (``XLA_FLAGS`` appended to the existing value)."""
    env = dict(os.environ, BRDF_INFER_CACHE=str(cache), JAX_PLATFORMS="cpu")
    for key, value in (extra or {}).items():
        if key == "XLA_FLAGS" and env.get("XLA_FLAGS"):
            env[key] = f"{env[key]} {value}"
        else:
            env[key] = value
    return env


def write_scenes(folder: Path, count: int) -> list[str]:
    """``count`` synthetic scenes of one model structure (the benchmark's: the bundled geometry,
    every reflectance scaled by its own factor)."""
    from benchmarks._batch import synthetic_scenes
    from brdf_infer.scene import load_scene

    folder.mkdir(parents=True, exist_ok=True)
    return synthetic_scenes(load_scene("lya"), count, folder)


def _nuts_options(settings: StressSettings) -> list[str]:
    return [
        "--chains",
        str(settings.chains),
        "--draws",
        str(settings.draws),
        "--warmup",
        str(settings.warmup),
    ]


def batch_command(
    folder: Path, settings: StressSettings, mode: str, devices: int = 1
) -> tuple[list[str], dict[str, str]]:
    """``brdf-infer batch`` over the scenes in ``folder/scenes`` in ``mode``."""
    scenes = sorted(str(p) for p in (folder / "scenes").glob("scene_*.toml"))
    argv = [sys.executable, "-c", _BOOTSTRAP, "batch", *scenes, "--mode", mode]
    argv += [*_nuts_options(settings), "--out", str(folder / f"out-{mode}"), "--json"]
    extra = (
        {"XLA_FLAGS": f"--xla_force_host_platform_device_count={devices}"} if devices > 1 else {}
    )
    return argv, extra


def posterior_command(folder: Path, settings: StressSettings) -> tuple[list[str], dict[str, str]]:
    """``brdf-infer posterior lya`` (NUTS)."""
    argv = [sys.executable, "-c", _BOOTSTRAP, "posterior", "lya", *_nuts_options(settings)]
    return [*argv, "--out", str(folder / "out-posterior"), "--json"], {}


def potential_command(folder: Path, settings: StressSettings) -> tuple[list[str], dict[str, str]]:
    """Threads evaluating the compiled, vmapped constraining map and potential of ``lya``."""
    del folder
    counts = (settings.points, settings.calls, settings.threads)
    return [sys.executable, "-c", POTENTIAL_SCRIPT, *map(str, counts)], {}


def shared_cache_command(
    folder: Path, settings: StressSettings
) -> tuple[list[str], dict[str, str]]:
    """``settings.processes`` processes at once of ``brdf-infer fit lya --method lsq`` on one
    fresh cache folder (:data:`SHARED_CACHE_SCRIPT`)."""
    del folder
    command = ["fit", "lya", "--method", "lsq", "--starts", "2", "--json"]
    return [sys.executable, "-c", SHARED_CACHE_SCRIPT, str(settings.processes), *command], {}


PATHS: dict[str, StressPath] = {
    "batch threads": StressPath(
        "batch threads", lambda f, s: batch_command(f, s, "threads"), needs_scenes=True
    ),
    "batch vmap, 2 forced CPU devices": StressPath(
        "batch vmap, 2 forced CPU devices",
        lambda f, s: batch_command(f, s, "vmap", devices=2),
        needs_scenes=True,
    ),
    "posterior lya": StressPath("posterior lya", posterior_command),
    "potential, threads": StressPath("potential, threads", potential_command),
    "four processes, one fresh cache": StressPath(
        "four processes, one fresh cache", shared_cache_command, most_repeats=5
    ),  # every repetition compiles cold, four times over: ≈ 75 s on 2 cores
}


def run_path(
    name: str,
    folder: Path,
    settings: StressSettings | None = None,
    *,
    cache: Path | None = None,
) -> Watched:
    """One repetition of path ``name`` in ``folder`` (its scenes written there on first use),
    compiled programs cached in ``cache`` (default ``folder/cache``)."""
    settings = settings or StressSettings()
    path = PATHS[name]
    folder.mkdir(parents=True, exist_ok=True)
    if path.needs_scenes and not (folder / "scenes").is_dir():
        write_scenes(folder / "scenes", settings.scenes)
    argv, extra = path.command(folder, settings)
    env = child_environment(cache or folder / "cache", extra)
    return run_watched(argv, timeout=settings.timeout, env=env, cwd=folder, label=name)


@dataclass(frozen=True)
class StressRow:
    """One path of the report: repetitions, how many hung (killed by the watchdog), how many
    failed otherwise, and the mean wall time of a repetition [s]."""

    path: str
    repetitions: int
    hangs: int
    failures: int
    seconds: float

    @property
    def cells(self) -> list[str]:
        return [
            self.path,
            str(self.repetitions),
            str(self.hangs),
            str(self.failures),
            f"{self.seconds:.1f}",
        ]


def stress_rows(
    repeats: int = 20,
    *,
    settings: StressSettings | None = None,
    paths: Sequence[str] | None = None,
    progress: Callable[[str], None] = print,
) -> list[StressRow]:
    """Every stress path ``repeats`` times (at most its ``most_repeats``), each repetition in
    a fresh process under the watchdog (``settings.timeout`` seconds). Each path gets a fresh
    compilation cache folder of its own, so its first repetition compiles (as a first run on a
    new machine does) and the others load the programs from it (the shared-cache path makes a
    new folder for every repetition)."""
    settings = settings or StressSettings()
    rows = []
    with tempfile.TemporaryDirectory(prefix="brdf_infer_stress_") as root:
        for index, name in enumerate(paths or list(PATHS)):
            folder = Path(root) / f"path{index}"
            hangs = failures = 0
            seconds = 0.0
            count = min(repeats, PATHS[name].most_repeats or repeats)
            for k in range(count):
                watched = run_path(name, folder, settings)
                seconds += watched.seconds
                hangs += watched.hung
                failures += not watched.hung and not watched.ok
                state = "hung" if watched.hung else ("ok" if watched.ok else "failed")
                progress(f"  stress {name}: {k + 1}/{count} {state} ({watched.seconds:.1f} s)")
            rows.append(StressRow(name, count, hangs, failures, seconds / count))
    return rows
