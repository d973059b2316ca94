"""Does ``brdf-infer design`` pay off over several rounds? A sequential study with known truths.

Each seed draws a truth from the bundled run's posterior (coating and noise scales), lets a
:class:`~brdf_infer.studies.synthetic.SyntheticLab` measure an initial data set (the scene's rows of
one series: the article's first, specular campaign) and fits it by NUTS. Then K rounds, each a
new session (a reference measurement of its own): three strategies each choose the round's rows
— ``design`` (greedy on the expected sd of TIS(θ) given that strategy's data so far), ``random``
(uniform among the reachable grid settings) and ``article`` (a plan like the article's: the
incidence angles 45°, 75°, 80° in turn, each scanned by δ = θs − θi = 0, −5, +5, −10, … within
the instrument's reach, Table 2) — the strategy's own copy of the lab measures them, the rows
join that strategy's data and NUTS fits them again. Every strategy of one seed starts from the
same initial data and goes on from the same lab state, random numbers and NUTS keys (common
random numbers), so paired differences between strategies measure where the rows were taken,
not luck. Reported per number of new rows: the mean 95 % width of TIS(θ), design's paired
differences to the others with their standard errors, and how often each interval covers the
true TIS(θ).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from benchmarks._design import (
    Fitter,
    concatenated,
    in_series,
    truth_lab,
    with_sessions,
)
from brdf_infer.design import (
    Candidates,
    DesignOptions,
    DesignRun,
    candidate_measurements,
    design,
    grid_candidates,
    load_design_run,
    reachable,
)
from brdf_infer.model import tis
from brdf_infer.model.params import DPHI_NAME, PARAM_NAMES, Params, with_dphi_scale
from brdf_infer.scene import Scene
from brdf_infer.tables.measurements import Measurements

STRATEGIES = ("design", "random", "article")
NAMES = {"design": "design", "random": "random reachable", "article": "the article's plan"}
ARTICLE_INCIDENCE_DEG = (45.0, 75.0, 80.0)
ARTICLE_DELTAS_DEG = (0, -5, 5, -10, 10, -15, 15)


@dataclass(frozen=True)
class PayoffSettings:
    """Seeds, rounds, rows per round and the NUTS settings of every fit."""

    seeds: int = 24
    rounds: int = 4
    rows_per_round: int = 2
    theta_i_deg: float = 70.0
    initial_series: str = "I"
    chains: int = 2
    warmup: int = 300
    draws: int = 500
    simulations: int = 128


def article_plan(scene: Scene, series: str, count: int) -> Candidates:
    """The first ``count`` settings of the article-like plan (module docstring) that the
    instrument reaches."""
    settings = []
    for delta in ARTICLE_DELTAS_DEG:
        for theta_i in ARTICLE_INCIDENCE_DEG:
            if reachable(scene.design, theta_i, theta_i + delta, np.nan):
                settings.append((theta_i, theta_i + delta))
    settings = settings[:count]
    return Candidates(
        np.full(len(settings), series),
        np.array([s[0] for s in settings]),
        np.array([s[1] for s in settings]),
        np.full(len(settings), np.nan),
    )


class _Study:
    """The study's fixed parts: the scene with one new session per round, the truths' source,
    the grid, the fits."""

    def __init__(self, run_dir: str | Path, settings: PayoffSettings):
        self.base, self.settings = load_design_run(run_dir), settings
        series = self.base.scene.design.series or "II"
        self.series = series
        self.sessions = [f"S{k + 1}" for k in range(settings.rounds)]
        self.scene = with_sessions(self.base.scene, series, self.sessions)
        measurements = self.base.measurements
        self.geometry = measurements.subset(measurements.series == settings.initial_series)
        self.grid = grid_candidates(self.scene.design, series)
        total = settings.rounds * settings.rows_per_round
        self.plan = article_plan(self.scene, series, total)
        self.fitter = Fitter(self.scene, settings.chains, settings.warmup, settings.draws)

    def tis(self, sites: dict) -> np.ndarray:
        """TIS at the study's angle of every draw: the products' (``[outputs] fold``), each
        draw's out-of-plane width where the run has one."""
        params = Params(*(jnp.asarray(sites[n]) for n in PARAM_NAMES))
        constants = self.scene.model.constants
        if DPHI_NAME in sites:
            constants = with_dphi_scale(constants, jnp.asarray(sites[DPHI_NAME]))
        angle = jnp.asarray(self.settings.theta_i_deg)
        fold = self.scene.outputs.fold
        return np.asarray(tis(angle, params, fold, constants)).reshape(-1)

    def interval(self, sites: dict, truth: float) -> tuple[float, bool]:
        """95 % width of TIS(θ) and whether the interval covers the truth."""
        low, high = np.quantile(self.tis(sites), [0.025, 0.975])
        return float(high - low), bool(low <= truth <= high)

    def _choose(self, strategy: str, data: Measurements, sites: dict, step: int, rng) -> Candidates:
        count = self.settings.rows_per_round
        if strategy == "design":
            run = DesignRun(self.scene, data, sites, self.base.path)
            options = DesignOptions(budget=count, seed=step, simulations=self.settings.simulations)
            chosen = design(run, f"tis:{self.settings.theta_i_deg:g}", self.grid, options).chosen
            return Candidates(
                np.full(count, self.series),
                np.array([c["theta_i_deg"] for c in chosen]),
                np.array([c["theta_s_deg"] for c in chosen]),
                np.full(count, np.nan),
            )
        if strategy == "random":
            return self.grid.subset(rng.choice(len(self.grid), count, replace=False))
        return self.plan.subset(np.arange(step * count, (step + 1) * count))

    def seed(self, seed: int) -> tuple[dict, list]:
        """One seed: {(strategy, rows added): (width, covered)} and design's chosen settings."""
        settings = self.settings
        rng = np.random.default_rng(seed)
        index = int(rng.integers(len(self.base.sites["brdf0"])))
        lab = truth_lab(self.scene, self.base.sites, index, 10_000 + seed)
        truth = float(self.tis({n: np.array([self.base.sites[n][index]]) for n in PARAM_NAMES})[0])
        initial = lab.measure(self.geometry)
        sites = self.fitter.fit(initial, seed)
        outcomes = {("initial", 0): self.interval(sites, truth)}
        chosen = []
        for strategy in STRATEGIES:
            own_lab, data, draws = lab.fork(), initial, sites
            own_rng = np.random.default_rng(50_000 + seed)
            for step, session in enumerate(self.sessions):
                candidates = self._choose(strategy, data, draws, step, own_rng)
                if strategy == "design":
                    chosen += list(zip(candidates.theta_i_deg, candidates.theta_s_deg, strict=True))
                rows = in_series(candidate_measurements(candidates, data), session)
                data = concatenated(data, own_lab.measure(rows))
                draws = self.fitter.fit(data, seed + 7 * (step + 1))
                added = (step + 1) * settings.rows_per_round
                outcomes[(strategy, added)] = self.interval(draws, truth)
        return outcomes, chosen


def payoff(
    run_dir: str | Path, settings: PayoffSettings = PayoffSettings(), progress=print
) -> dict:
    """The sequential study (module docstring).

    Returns:
        ``widths`` and ``covered`` per ``"strategy:rows"`` (one entry per seed), ``rows`` (the
        numbers of new rows), ``chosen`` (design's settings, all seeds), ``initial_rows``,
        ``seeds``, ``theta_i_deg``, ``seconds``.
    """
    start = time.perf_counter()
    study = _Study(run_dir, settings)
    outcomes, chosen = [], []
    for seed in range(settings.seeds):
        outcome, picked = study.seed(seed)
        outcomes.append(outcome)
        chosen += picked
        progress(f"  design pay-off seed {seed + 1}/{settings.seeds}")
    keys = list(outcomes[0])
    label = {key: f"{key[0]}:{key[1]}" for key in keys}
    return {
        "widths": {label[k]: [o[k][0] for o in outcomes] for k in keys},
        "covered": {label[k]: int(sum(o[k][1] for o in outcomes)) for k in keys},
        "rows": [settings.rows_per_round * (k + 1) for k in range(settings.rounds)],
        "chosen": [(float(i), float(s)) for i, s in chosen],
        "initial_rows": len(study.geometry),
        "initial_series": settings.initial_series,
        "series": study.series,
        "seeds": settings.seeds,
        "theta_i_deg": settings.theta_i_deg,
        "seconds": time.perf_counter() - start,
    }


HEADERS = [
    "new rows",
    "chosen by",
    "mean 95 % width of TIS [%]",
    "vs initial",
    "design minus this, paired [%]",
    "design narrower",
    "covers truth",
]


def _paired(result: dict, rows: int, strategy: str) -> tuple[float, float, int]:
    """Design minus ``strategy`` at ``rows`` new rows [per cent TIS]: mean, standard error,
    and the seeds in which design's width is the smaller."""
    chosen = np.asarray(result["widths"][f"design:{rows}"])
    other = np.asarray(result["widths"][f"{strategy}:{rows}"])
    difference = 100 * (chosen - other)
    error = np.std(difference, ddof=1) / np.sqrt(len(difference)) if len(difference) > 1 else np.nan
    return float(np.mean(difference)), float(error), int(np.sum(chosen < other))


def payoff_rows(result: dict) -> list[list[str]]:
    """Markdown table rows of :func:`payoff`."""
    widths = {k: np.asarray(v) for k, v in result["widths"].items()}
    initial, seeds = float(np.mean(widths["initial:0"])), result["seeds"]
    rows = [
        [
            "0",
            "none (initial data)",
            f"{100 * initial:.3f}",
            "1.000",
            "—",
            "—",
            f"{result['covered']['initial:0']}/{seeds}",
        ],
    ]
    for count in result["rows"]:
        for strategy in STRATEGIES:
            key = f"{strategy}:{count}"
            paired = narrower = "—"
            if strategy != "design":
                mean, error, wins = _paired(result, count, strategy)
                paired, narrower = f"{mean:+.3f} ± {error:.3f}", f"{wins}/{seeds}"
            mean_width = float(np.mean(widths[key]))
            rows.append(
                [
                    str(count),
                    NAMES[strategy],
                    f"{100 * mean_width:.3f}",
                    f"{mean_width / initial:.3f}",
                    paired,
                    narrower,
                    f"{result['covered'][key]}/{seeds}",
                ]
            )
    return rows


def payoff_figure(result: dict) -> bytes:
    """PNG: the mean 95 % width of TIS(θ) against the number of new rows per strategy (± one
    standard error over seeds), and design's paired differences to the others (± two)."""
    from matplotlib.figure import Figure

    from brdf_infer.report import png

    figure = Figure(figsize=(11.0, 4.2), layout="constrained")
    left, right = figure.subplots(1, 2)
    counts = [0, *result["rows"]]
    seeds = result["seeds"]
    for strategy in STRATEGIES:
        series = [result["widths"]["initial:0"]]
        series += [result["widths"][f"{strategy}:{n}"] for n in result["rows"]]
        means = [100 * np.mean(s) for s in series]
        errors = [100 * np.std(s, ddof=1) / np.sqrt(seeds) if seeds > 1 else 0 for s in series]
        left.errorbar(counts, means, yerr=errors, marker="o", capsize=3, label=NAMES[strategy])
    left.set_xticks(counts)
    left.set_xlabel("new rows (one session per round)")
    left.set_ylabel(f"mean 95 % width of TIS({result['theta_i_deg']:g}°) [%]")
    left.legend()
    for strategy in STRATEGIES[1:]:
        pairs = [_paired(result, n, strategy) for n in result["rows"]]
        right.errorbar(
            result["rows"],
            [p[0] for p in pairs],
            yerr=[2 * p[1] for p in pairs],
            marker="o",
            capsize=3,
            label=f"design − {NAMES[strategy]}",
        )
    right.axhline(0.0, color="0.5", lw=0.8)
    right.set_xticks(result["rows"])
    right.set_xlabel("new rows (one session per round)")
    right.set_ylabel("paired width difference [% TIS] (± 2 se)")
    right.legend()
    figure.suptitle(f"Sequential design study: {seeds} truths from the bundled posterior")
    return png(figure)
