"""The benchmark report's section on the peers: nutpie and PyMC NUTS on the same posterior as
``brdf-infer posterior`` (:mod:`._peers`, :mod:`._peers_runs`)."""

from __future__ import annotations

import numpy as np

from benchmarks._peers import missing_peers
from benchmarks._peers_check import relative_spread
from benchmarks._peers_runs import LABELS, QUANTITIES, peer_rows
from benchmarks._tables import markdown_table

HEADERS = [
    "sampler",
    "BLAS threads",
    "cold [s]",
    "warm [s]",
    "sampling (warm) [s]",
    "min bulk ESS",
    "divergences",
    "leapfrog steps / draw",
    "ESS / warm s",
    "|Δ median| / sd: " + ", ".join(LABELS[q] for q in QUANTITIES),
]


def peer_section(quick: bool, progress=print, *, repeat: int = 1) -> str:
    """The report's section (Markdown, ending in a blank line): one line when the ``peers``
    extra is missing."""
    heading = "## Peers: nutpie and PyMC NUTS on the same posterior\n\n"
    missing = missing_peers()
    if missing:
        return (
            heading + f"Skipped: {' and '.join(missing)} not installed "
            '(`pip install -e ".[peers]"`).\n'
        )
    from brdf_infer.scene import load_scene

    progress("benchmark (peers): nutpie and PyMC NUTS ...")
    scene = load_scene("lya")
    rows, (ours, theirs) = peer_rows(scene, quick, progress, repeat=repeat)
    difference = theirs - ours
    spread = float(np.max(np.abs(difference - np.median(difference))))
    relative = relative_spread(ours, theirs)
    import nutpie
    import pymc

    draws = 250 if quick else 1000
    return (
        heading + f"The posterior of `lya` written in PyMC {pymc.__version__} "
        "(`benchmarks._peers`: the same 42 rows, priors and generative error model, "
        "one `pm.MvNormal` with covariance D + W Wᵀ and the analytic angle slopes) and sampled "
        f"by nutpie {nutpie.__version__} (numba backend) and by PyMC's NUTS (`pm.sample`), "
        f"4 chains × ({draws} warmup + {draws} draws), seed 0, against `brdf-infer posterior "
        "lya` (dense mass matrix on the whitened coordinates, the same posterior over the "
        "physical parameters). Log density against our unwhitened model at "
        f"{len(ours)} points (half from the prior, half near the posterior): PyMC − ours = "
        f"{float(np.median(difference)):.3g} everywhere to {spread:.1e} "
        f"(at most {relative:.1e} of the point's |log p|).\n\n"
        "Wall time end to end in a fresh process: interpreter start, imports, building and "
        "compiling the model, sampling, and the run's output (ours writes its whole run "
        "folder: PSIS-LOO, posterior predictive, bands; a peer saves its draws). Cold: empty "
        "compilation caches (ours: `BRDF_INFER_CACHE`, JAX's persistent cache; PyMC: "
        "PyTensor's `compiledir`, its C modules; nutpie: `compiledir` and `NUMBA_CACHE_DIR`); "
        f"warm: the same caches again{'' if repeat == 1 else f', best of {repeat}'}"
        f"{' (no warm runs: ESS per cold second)' if repeat == 0 else ''}. BLAS 1: "
        "`OMP_NUM_THREADS=OPENBLAS_NUM_THREADS=MKL_NUM_THREADS=1`; default: those unset "
        "(`pm.sample` then limits BLAS to its `cores` itself, `blas_cores='auto'`). Min bulk "
        "ESS over BRDF0, α, θs0 and TIS(70°) (Eq. 9 with Eq. 10 per draw); ESS / warm s "
        "divides it by the warm wall time; leapfrog steps per draw after warmup (the cost "
        "of a draw in gradients); |Δ median| / sd against ours, in our posterior "
        "sd. Rows without a warm run (PyMC NUTS, nutpie with default BLAS threading) divide "
        "by the cold time. PyMC NUTS with pip's default BLAS threading is not rerun here: "
        "measured earlier on this 2-core machine with the same model it took 2066 s against "
        "324 s pinned to one thread.\n\n"
        + markdown_table(HEADERS, [row.cells for row in rows])
        + "\n"
    )
