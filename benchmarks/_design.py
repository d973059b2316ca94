"""Benchmark of ``brdf-infer design``: its expected sd ratio against refits of data from an
independent simulation.

What design estimates for one new row at a setting x is E_y[sd(T | D, y)] / sd(T | D), from the
run's posterior draws and its own Gaussian conditional predictive of y. The check here shares
neither: each replicate draws a truth from the bundled run's posterior (the coating and the
noise scales), lets a :class:`~brdf_infer.studies.synthetic.SyntheticLab` measure the initial rows D
(the scene's geometry) and then the new row in a new session (its own reference measurement,
its own rotation setting, the sample effect of the sample it is taken on — drawn term by term,
the angle errors moving the angles), fits D alone and D with the row by NUTS with the same keys
(common random numbers), and asks design the same question on the replicate's posterior of D.
Per candidate (the best, the median and the worst of design's grid on the run) it reports the
mean estimate and the mean refit ratio sd(D, y)/sd(D) with their Monte Carlo errors (spread over
√replicates) and their paired difference; and whether the refits can rank the candidates at all
(a paired difference of refit ratios beyond two of its standard errors).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from brdf_infer.design import (
    Candidates,
    DesignOptions,
    DesignRun,
    candidate_measurements,
    design,
    load_design_run,
    parse_target,
    target_values,
)
from brdf_infer.model.params import DPHI_NAME, PARAM_NAMES, Params
from brdf_infer.posterior import NutsProgram, build_model_data, build_posterior_model, chain_keys
from brdf_infer.scene import Scene
from brdf_infer.studies.synthetic import SyntheticLab
from brdf_infer.tables.measurements import Measurements

HEADERS = [
    "candidate",
    "θi [deg]",
    "θs [deg]",
    "estimate: sd ratio (± MC)",
    "refits: sd ratio (± MC)",
    "refit − estimate (± se)",
    "replicates",
]
NOISE_SITES = ("sample_sd", "repeatability")


@dataclass(frozen=True)
class RefitSettings:
    """Replicates, the NUTS settings of every fit, and design's settings.

    Attributes:
        initial_series: the initial rows are the scene's rows of this series only (None: all).
    """

    replicates: int = 8
    chains: int = 2
    warmup: int = 300
    draws: int = 500
    seed: int = 0
    simulations: int = 128
    initial_series: str | None = None


def concatenated(first: Measurements, second: Measurements) -> Measurements:
    """The rows of ``first`` then ``second`` (both in the plane)."""
    fields = {
        name: np.concatenate([getattr(first, name), getattr(second, name)])
        for name in ("series", "sample", "theta_i_deg", "theta_s_deg", "reflectance")
    }
    error = None
    if first.reflectance_err is not None and second.reflectance_err is not None:
        error = np.concatenate([first.reflectance_err, second.reflectance_err])
    return Measurements(
        path=first.path, quantity=first.quantity, phi_s_deg=None, reflectance_err=error, **fields
    )


def with_sessions(scene: Scene, like: str, names: list[str]) -> Scene:
    """``scene`` with series ``names`` (new sessions) taking the aperture of series ``like``."""
    return replace(scene, series={**scene.series, **{n: scene.series[like] for n in names}})


def in_series(rows: Measurements, name: str) -> Measurements:
    """``rows`` relabelled as measured in series (session) ``name``."""
    return replace(rows, series=np.full(len(rows), name))


class Fitter:
    """NUTS fits of one scene's data sets, one compiled program per row count."""

    def __init__(self, scene: Scene, chains: int, warmup: int, draws: int):
        self.scene, self.chains, self.warmup, self.draws = scene, chains, warmup, draws
        self.programs: dict[int, NutsProgram] = {}

    def fit(self, measurements: Measurements, seed: int) -> dict[str, np.ndarray]:
        """Draws (flattened over chains) of the parameters (Eq. 8's width factor too, where the
        scene leaves it uncertain) and the learned noise scales."""
        rows = len(measurements)
        if rows not in self.programs:
            model = build_posterior_model(self.scene, measurements)
            self.programs[rows] = NutsProgram(model, warmup=self.warmup)
        output = self.programs[rows].run(
            build_model_data(self.scene, measurements),
            chain_keys(seed, 1, self.chains)[0],
            self.draws,
        )
        names = [*PARAM_NAMES, DPHI_NAME, *NOISE_SITES]
        return {n: np.reshape(output.sites[n], -1) for n in names if n in output.sites}


def truth_lab(scene: Scene, sites: dict, index: int, seed: int) -> SyntheticLab:
    """A lab whose coating and noise scales are draw ``index`` of ``sites``."""
    params = Params(*(float(sites[n][index]) for n in PARAM_NAMES))
    noise = [float(sites[n][index]) if n in sites else 0.0 for n in NOISE_SITES]
    return SyntheticLab(scene, params, *noise, seed)


def target_sd(target, sites: dict, scene: Scene) -> float:
    """Posterior sd of a one-valued target over ``sites``."""
    return float(np.std(target_values(target, sites, scene)[:, 0]))


def _mean_error(values) -> tuple[float, float]:
    values = np.asarray(values, float)
    error = np.std(values, ddof=1) / np.sqrt(len(values)) if len(values) > 1 else np.nan
    return float(np.mean(values)), float(error)


def _picks(run: DesignRun, target, settings: RefitSettings) -> tuple[dict, Candidates]:
    """Design's best, median and worst grid candidate on the run, as candidates."""
    options = DesignOptions(budget=1, seed=settings.seed, simulations=settings.simulations)
    ordered = design(run, target, options=options).candidates
    picks = {"best": ordered[0], "median": ordered[len(ordered) // 2], "worst": ordered[-1]}
    entries = list(picks.values())
    candidates = Candidates(
        np.array([e["series"] for e in entries]),
        np.array([e["theta_i_deg"] for e in entries]),
        np.array([e["theta_s_deg"] for e in entries]),
        np.full(len(entries), np.nan),
    )
    return picks, candidates


def refit_check(
    run_dir: str | Path,
    target: str = "tis:70",
    settings: RefitSettings = RefitSettings(),
    progress=print,
) -> dict:
    """Estimate against independent refits (module docstring).

    Returns:
        ``rows``: per candidate ``pick``, θi, θs, ``estimate`` and ``refit`` (mean ratio, MC
        error), ``difference`` (refit − estimate: mean, se), ``replicates``; ``ranks``: per pair
        of candidates the paired difference of refit ratios (mean, se) and whether it ranks
        them; ``initial_rows``, ``seconds``.
    """
    start = time.perf_counter()
    base = load_design_run(run_dir)
    parsed = parse_target(target)
    picks, candidates = _picks(base, parsed, settings)
    series = str(candidates.series[0])
    scene = with_sessions(base.scene, series, ["N1"])
    geometry = base.measurements
    if settings.initial_series is not None:
        geometry = geometry.subset(geometry.series == settings.initial_series)
    fitter = Fitter(scene, settings.chains, settings.warmup, settings.draws)
    rng = np.random.default_rng(settings.seed)
    estimates, refits = [], []
    options = DesignOptions(budget=1, seed=settings.seed, simulations=settings.simulations)
    for replicate in range(settings.replicates):
        index = int(rng.integers(len(base.sites["brdf0"])))
        lab = truth_lab(scene, base.sites, index, 1000 * settings.seed + replicate)
        initial = lab.measure(geometry)
        seed = 100 * settings.seed + replicate
        sites = fitter.fit(initial, seed)
        today = target_sd(parsed, sites, scene)
        run = DesignRun(scene, initial, sites, base.path)
        answers = design(run, parsed, candidates, options, series=series).candidates
        by_setting = {(a["theta_i_deg"], a["theta_s_deg"]): a["sd_ratio"] for a in answers}
        estimates.append([by_setting[(e["theta_i_deg"], e["theta_s_deg"])] for e in picks.values()])
        ratios = []
        for k in range(len(candidates)):
            row = in_series(candidate_measurements(candidates.subset([k]), initial), "N1")
            measured = lab.fork().measure(row)  # each candidate the same lab's next row
            ratios.append(
                target_sd(parsed, fitter.fit(concatenated(initial, measured), seed), scene) / today
            )
        refits.append(ratios)
        progress(f"  design refit check {replicate + 1}/{settings.replicates}")
    estimates, refits = np.array(estimates), np.array(refits)
    rows = []
    for k, (pick, entry) in enumerate(picks.items()):
        rows.append(
            {
                "pick": pick,
                "theta_i_deg": entry["theta_i_deg"],
                "theta_s_deg": entry["theta_s_deg"],
                "estimate": _mean_error(estimates[:, k]),
                "refit": _mean_error(refits[:, k]),
                "difference": _mean_error(refits[:, k] - estimates[:, k]),
                "replicates": settings.replicates,
            }
        )
    names = list(picks)
    ranks = []
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            mean, error = _mean_error(refits[:, a] - refits[:, b])
            ranks.append(
                {
                    "pair": (names[a], names[b]),
                    "difference": (mean, error),
                    "ranked": abs(mean) > 2 * error,
                }
            )
    return {
        "rows": rows,
        "ranks": ranks,
        "initial_rows": len(geometry),
        "initial_series": settings.initial_series,
        "seconds": time.perf_counter() - start,
    }


def refit_rows(result: dict) -> list[list[str]]:
    """Markdown table rows of :func:`refit_check`."""

    def pm(pair: tuple[float, float], signed: bool = False) -> str:
        return f"{pair[0]:{'+' if signed else ''}.3f} ± {pair[1]:.3f}"

    return [
        [
            r["pick"],
            f"{r['theta_i_deg']:g}",
            f"{r['theta_s_deg']:g}",
            pm(r["estimate"]),
            pm(r["refit"]),
            pm(r["difference"], signed=True),
            str(r["replicates"]),
        ]
        for r in result["rows"]
    ]


def rank_line(result: dict) -> str:
    """Which candidates the refits rank (paired differences of their ratios)."""
    parts = []
    for rank in result["ranks"]:
        mean, error = rank["difference"]
        verdict = "ranked" if rank["ranked"] else "not ranked by these refits"
        parts.append(f"{rank['pair'][0]} − {rank['pair'][1]} {mean:+.3f} ± {error:.3f} ({verdict})")
    return "Refit ratio differences, paired by replicate: " + "; ".join(parts) + "."
