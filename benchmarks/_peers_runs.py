"""The peers' runs: ``brdf-infer posterior`` and each peer sampler (:data:`PEER_RUNS`) in fresh
processes, cold and warm, and the statistics of their draws in the physical parameters."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks import _peers
from benchmarks._peers import (
    ANGLE_SCALE_DEG,
    PARAMETER_SITES,
    PRIOR_NAMES,
    model_arrays,
)
from benchmarks._peers_check import log_density_check
from brdf_infer.runs.folder import RunFolder

QUANTITIES = ("brdf0", "alpha", "theta_s0", "tis70")
LABELS = {"brdf0": "BRDF0", "alpha": "α", "theta_s0": "θs0", "tis70": "TIS(70°)"}
ONE_THREAD = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
PEERS_FILE = Path(_peers.__file__)  # what a peer's process loads by path and runs


def _run_child(arrays: Path, sampler: str, out: Path, settings, env: dict, blas: str = "auto"):
    """Wall time of one peer process and what it saved."""
    bootstrap = (
        "import importlib.util, sys; "
        f"spec = importlib.util.spec_from_file_location('_brdf_peers', {str(PEERS_FILE)!r}); "
        "module = sys.modules['_brdf_peers'] = importlib.util.module_from_spec(spec); "
        "spec.loader.exec_module(module); "
        "module._child(sys.argv[1:])"
    )
    argv = [str(arrays), sampler, str(out), *(str(s) for s in settings), blas]
    clock = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-c", bootstrap, *argv], capture_output=True, text=True, env=env
    )
    seconds = time.perf_counter() - clock
    if done.returncode != 0:
        raise RuntimeError(f"{sampler} failed:\n{done.stderr[-3000:]}")
    with np.load(out) as stored:
        result = {key: np.asarray(value) for key, value in stored.items()}
    return seconds, result


def _run_ours(scene: str, out: Path, cache: Path, settings, env: dict):
    """Wall time of one ``brdf-infer posterior SCENE --json`` process, its summary, draws and
    mean leapfrog steps per draw."""
    from brdf_infer._internal import arviz as az

    chains, warmup, draws, seed = settings
    argv = [
        "posterior",
        scene,
        "--json",
        "--out",
        str(out),
        *("--chains", str(chains), "--warmup", str(warmup), "--draws", str(draws)),
        *("--seed", str(seed)),
    ]
    clock = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "brdf_infer", *argv],
        capture_output=True,
        text=True,
        env=dict(env, BRDF_INFER_CACHE=str(cache)),
    )
    seconds = time.perf_counter() - clock
    if done.returncode != 0:
        raise RuntimeError(f"brdf-infer posterior failed:\n{done.stderr[-3000:]}")
    summary = json.loads(done.stdout)
    idata = az.from_netcdf(RunFolder(out).posterior_file)
    sites = {name: np.asarray(idata.posterior[name]) for name in idata.posterior.data_vars}
    return seconds, summary, sites, float(idata.sample_stats["n_steps"].mean())


def physical_draws(sites: dict[str, np.ndarray], scene) -> dict[str, np.ndarray]:
    """BRDF0, α, θs0 and TIS(70°) of every draw, shape (chains, draws): from the paper-unit
    parameters (ours) or from the internal sites (a peer's), TIS by Eq. (9) with the scene's
    fold switch, as every TIS band of a run (``brdf_infer.posterior._bands``)."""
    from brdf_infer.model import tis
    from brdf_infer.model.coordinates import from_internal
    from brdf_infer.model.params import Params

    shape = next(iter(sites.values())).shape[:2]
    if "brdf0" in sites:
        params = Params(*(np.asarray(sites[name]) for name in Params._fields))
    else:
        internal = []
        for site, name in zip(PARAMETER_SITES, PRIOR_NAMES, strict=True):
            prior = scene.priors[name]
            scale = ANGLE_SCALE_DEG if name == "theta_s0" else 1.0
            internal.append(sites[site] if site in sites else np.full(shape, prior.value / scale))
        alpha, t_s0, log_brdf0, b1, b2, b3 = internal
        params = Params(
            *(
                np.asarray(value)
                for value in from_internal(np.stack([log_brdf0, b1, b2, b3, alpha, t_s0], -1))
            )
        )
    flat = Params(*(np.broadcast_to(value, shape).reshape(-1) for value in params))
    model = scene.model
    tis70 = np.asarray(tis(np.asarray(70.0), flat, model.fold, model.constants)).reshape(shape)
    return {
        "brdf0": np.asarray(params.brdf0).reshape(shape),
        "alpha": np.broadcast_to(params.alpha, shape),
        "theta_s0": np.broadcast_to(params.theta_s0, shape),
        "tis70": tis70,
    }


@dataclass(frozen=True)
class PeerRow:
    sampler: str
    blas: str
    cold: float
    warm: float | None  # None: no warm run (``repeat=0``)
    sampling: float  # of the warm run: the sampler's iterations (ours: summary seconds)
    min_ess: float
    divergences: int
    steps: float  # mean leapfrog steps per draw (after warmup)
    agreement: dict[str, float] | None  # |Δ median| / sd against ours; None for ours

    @property
    def cells(self) -> list[str]:
        agreement = (
            "reference"
            if self.agreement is None
            else ", ".join(f"{self.agreement[q]:.2f}" for q in QUANTITIES)
        )
        return [
            self.sampler,
            self.blas,
            f"{self.cold:.1f}",
            "–" if self.warm is None else f"{self.warm:.1f}",
            f"{self.sampling:.1f}",
            f"{self.min_ess:.0f}",
            str(self.divergences),
            f"{self.steps:.0f}",
            f"{self.min_ess / (self.cold if self.warm is None else self.warm):.1f}",
            agreement,
        ]


def _statistics(draws: dict[str, np.ndarray]) -> tuple[float, dict, dict]:
    from brdf_infer._internal import arviz as az

    ess = min(float(az.ess(np.asarray(draws[q]), method="bulk")) for q in QUANTITIES)
    medians = {q: float(np.median(draws[q])) for q in QUANTITIES}
    sds = {q: float(np.std(draws[q])) for q in QUANTITIES}
    return ess, medians, sds


# (label, sampler, BLAS label, BLAS pinned to one thread by the environment). Unpinned,
# ``pm.sample`` still limits each of its worker processes to one BLAS thread itself
# (``blas_cores="auto"``); nutpie's threads and their OpenBLAS calls are left alone.
# (label, sampler, BLAS threads, pinned to one thread, warm run too). PyMC's NUTS needs
# ≈ 136 leapfrog steps per draw on this posterior (≈ 5–10 min a run on 2 cores), and with
# pip's default BLAS threading several times that: it runs cold only, pinned only.
PEER_RUNS = (
    ("nutpie (low-rank mass)", "nutpie-low-rank", "1", True, True),
    ("nutpie (low-rank mass)", "nutpie-low-rank", "default", False, False),
    ("nutpie (diagonal mass)", "nutpie", "1", True, True),
    ("PyMC NUTS", "pymc", "1", True, False),
)


def peer_rows(
    scene,
    quick: bool,
    progress=print,
    *,
    repeat: int = 1,
    draws: int | None = None,
    warmup: int | None = None,
) -> tuple[list[PeerRow], tuple[np.ndarray, np.ndarray]]:
    """The rows of the section, and (ours, PyMC's) log densities of the 20-point check.

    Each sampler runs 1 + ``repeat`` times in fresh processes: cold (empty compilation
    caches), then warm (the same caches; the best wall time of ``repeat``; none with 0: the
    full PyMC runs take long); the statistics
    come from the last warm run. 4 chains, seed 0; ``draws`` and ``warmup`` per chain default
    to ours (1000 and 1000; quick: 250 and 250).
    """
    draws = draws or (250 if quick else 1000)
    warmup = warmup or (250 if quick else 1000)
    settings = (4, warmup, draws, 0)
    measurements = scene.load_measurements()
    progress("  log density against PyMC's at 20 points ...")
    check = log_density_check(scene, measurements)
    base = {key: value for key, value in os.environ.items() if key not in ONE_THREAD}
    pinned = dict(base, **ONE_THREAD)
    with tempfile.TemporaryDirectory() as temporary:
        folder = Path(temporary)
        arrays = folder / "arrays.npz"
        np.savez(arrays, **model_arrays(scene, measurements))
        ours, medians, sds = _our_row(scene, folder, settings, pinned, repeat, progress)
        rows = [ours]
        for k, (label, sampler, blas, one_thread, warm) in enumerate(PEER_RUNS):
            caches = folder / f"caches_{k}"
            env = dict(
                pinned if one_thread else base,
                PYTENSOR_FLAGS=f"compiledir={caches / 'pytensor'}",
                NUMBA_CACHE_DIR=str(caches / "numba"),
            )
            times = []
            for attempt in range(1 + (repeat if warm else 0)):
                progress(f"  {label}, BLAS {blas}, {'cold' if attempt == 0 else 'warm'}")
                seconds, result = _run_child(
                    arrays, sampler, folder / f"{k}_{attempt}.npz", settings, env
                )
                times.append(seconds)
            rows.append(_peer_row(scene, label, blas, times, result, medians, sds))
    return rows, check


def _our_row(
    scene, folder: Path, settings, env: dict, repeat: int, progress
) -> tuple[PeerRow, dict[str, float], dict[str, float]]:
    """Our row (``brdf-infer posterior`` cold, then ``repeat`` times warm), and the medians and
    sds of our draws that the peers are compared with."""
    times = []
    for attempt in range(1 + repeat):
        progress(f"  brdf-infer posterior {scene.name}, {'cold' if attempt == 0 else 'warm'}")
        out = folder / f"ours_{attempt}"
        seconds, summary, sites, steps = _run_ours(
            str(scene.path), out, folder / "ours_cache", settings, env
        )
        times.append(seconds)
    reference = physical_draws(sites, scene)
    ess, medians, sds = _statistics(reference)
    row = PeerRow(
        "ours (NumPyro NUTS, dense mass, whitened)",
        "1",
        times[0],
        min(times[1:], default=None),
        summary["seconds"]["sampling"],
        ess,
        int(summary["diagnostics"]["divergences"]),
        steps,
        None,
    )
    return row, medians, sds


def _peer_row(scene, label: str, blas: str, times: list[float], result: dict, medians, sds):
    """A peer's row from its wall times [s] and what its last process saved (``result``),
    compared with our ``medians`` in our ``sds``."""
    sites = {
        key.removeprefix("site_"): value for key, value in result.items() if key.startswith("site_")
    }
    ess, peer_medians, _ = _statistics(physical_draws(sites, scene))
    return PeerRow(
        label,
        blas,
        times[0],
        min(times[1:], default=None),
        float(result["seconds"][2]),
        ess,
        int(result["divergences"]),
        float(result["steps"]),
        {q: abs(peer_medians[q] - medians[q]) / sds[q] for q in QUANTITIES},
    )
