"""Does ``brdf-infer design`` pay off? A synthetic experiment with a known truth.

Each seed: a truth (the parameters and noise scales of the scene's run, their posterior
medians), an initial data set simulated from the generative error model at the scene's own
measured geometry, its NUTS posterior; then K new rows chosen three ways — by ``design``
(greedy on the joint expected sd of TIS(θ)), at random among the feasible grid settings, and
at the article's kind of settings (series II's near-specular geometry, θi ∈ {45°, 75°, 80°},
θs = θi + δ, |δ| ≤ 15°, Table 2) — simulated from the truth *given the initial data* (the new
rows share the calibration, sample and rotation effects the initial rows carry: the
conditional of :mod:`brdf_infer.design._estimate` with the truth as the one draw), appended,
and fitted again by NUTS. Reported per strategy: the mean 95 % width of TIS(θ) and how often
it covers the true TIS(θ). Every fit of one row count runs through one compiled program.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from brdf_infer.bench._design import HEADERS as REFIT_HEADERS
from brdf_infer.bench._design import RefitSettings, _augmented, refit_check, refit_rows
from brdf_infer.bench._tables import markdown_table, timed_command
from brdf_infer.design import (
    Candidates,
    DesignOptions,
    DesignRun,
    candidate_measurements,
    design,
    grid_candidates,
    load_design_run,
    predictive,
)
from brdf_infer.measurements import Measurements
from brdf_infer.model import tis
from brdf_infer.params import PARAM_NAMES, Params
from brdf_infer.posterior import (
    NutsProgram,
    build_model_data,
    build_posterior_model,
    chain_keys,
    run_posterior,
)
from brdf_infer.scene import Scene, load_scene

STRATEGIES = ("initial", "design", "random", "article")
HEADERS = [
    "rows added",
    "chosen by",
    "mean 95 % width of TIS [%]",
    "vs initial",
    "design minus this, paired [%]",
    "design narrower",
    "covers truth",
]


@dataclass(frozen=True)
class PayoffSettings:
    """Seeds, budgets, the initial design and the NUTS settings of every fit.

    Attributes:
        initial_series: the initial design keeps the scene's measured geometry of this series
            only (None: every row); new rows join it when set, else ``series``.
        series: the series new rows join when every row is kept.
    """

    seeds: int = 5
    budgets: tuple[int, ...] = (1, 3)
    theta_i_deg: float = 70.0
    chains: int = 2
    warmup: int = 300
    draws: int = 500
    series: str = "II"
    initial_series: str | None = None


def _truth(run: DesignRun) -> dict[str, np.ndarray]:
    """Posterior medians of the run's sites, as one draw."""
    return {name: np.median(values)[None] for name, values in run.sites.items()}


def _simulate(run: DesignRun, candidates: Candidates, truth: dict, normals) -> np.ndarray:
    """The new rows' ln R from the truth given the run's (initial) rows, jointly; ``normals``
    are the standard normal deviates (shared by the strategies of one seed)."""
    conditional = predictive(run, candidates, truth)
    loading = np.asarray(conditional.loading[0])
    covariance = loading @ loading.T + np.diag(np.asarray(conditional.own[0]))
    return np.asarray(conditional.mean[0]) + np.linalg.cholesky(covariance) @ normals


def _article(rng, budget: int, series: str) -> Candidates:
    settings = [(i, i + d) for i in (45.0, 75.0, 80.0) for d in range(-15, 16, 5) if i + d < 90]
    picked = [settings[k] for k in rng.choice(len(settings), budget, replace=False)]
    return Candidates(
        np.full(budget, series),
        np.array([p[0] for p in picked]),
        np.array([p[1] for p in picked]),
        np.full(budget, np.nan),
    )


def _subset(candidates: Candidates, index) -> Candidates:
    index = np.asarray(index, int)
    return Candidates(
        candidates.series[index],
        candidates.theta_i_deg[index],
        candidates.theta_s_deg[index],
        candidates.phi_s_deg[index],
    )


def _design_rows(picked: list[dict]) -> Candidates:
    return Candidates(
        np.array([c["series"] for c in picked]),
        np.array([c["theta_i_deg"] for c in picked]),
        np.array([c["theta_s_deg"] for c in picked]),
        np.full(len(picked), np.nan),
    )


class _Experiment:
    """The pay-off experiment's fixed parts: the scene, the truth, the candidate grid and one
    compiled NUTS program per data shape."""

    def __init__(self, base: DesignRun, settings: PayoffSettings):
        self.scene, self.settings = base.scene, settings
        geometry, self.series = base.measurements, settings.series
        if settings.initial_series is not None:
            geometry = geometry.subset(geometry.series == settings.initial_series)
            self.series = settings.initial_series
        self.geometry, self.path = geometry, base.path
        self.truth = _truth(base)
        self.true_tis = float(self.tis(self.truth)[0])
        self.grid = grid_candidates(self.scene.design, self.series)
        self.programs: dict[int, NutsProgram] = {}

    def tis(self, draws: dict) -> np.ndarray:
        """TIS(θ) of each draw."""
        params = Params(*(jnp.asarray(draws[n]) for n in PARAM_NAMES))
        model = self.scene.model
        angle = jnp.asarray(self.settings.theta_i_deg)
        return np.asarray(tis(angle, params, model.fold, model.constants))

    def fit(self, measurements: Measurements, seed: int) -> dict[str, np.ndarray]:
        """NUTS draws of the parameters and noise scales given ``measurements``."""
        rows, settings = len(measurements), self.settings
        if rows not in self.programs:
            model = build_posterior_model(self.scene, measurements)
            self.programs[rows] = NutsProgram(model, warmup=settings.warmup)
        output = self.programs[rows].run(
            build_model_data(self.scene, measurements),
            chain_keys(seed, 1, settings.chains)[0],
            settings.draws,
        )
        names = [*PARAM_NAMES, "sample_sd", "repeatability"]
        return {n: np.reshape(output.sites[n], -1) for n in names if n in output.sites}

    def interval(self, draws: dict) -> tuple[float, float, bool]:
        """95 % width and sd of TIS(θ), and whether the interval covers the true TIS."""
        values = self.tis(draws)
        low, high = np.quantile(values, [0.025, 0.975])
        return float(high - low), float(np.std(values)), bool(low <= self.true_tis <= high)

    def initial_data(self, rng) -> Measurements:
        """The initial design's rows simulated from the truth by the generative error model."""
        geometry = self.geometry
        parts = build_posterior_model(self.scene, geometry).draw_parts(self.truth)
        noise = np.asarray(parts.factor[0]) @ rng.standard_normal(parts.factor.shape[2])
        noise += np.sqrt(np.asarray(parts.diagonal[0])) * rng.standard_normal(len(geometry))
        empty = geometry.subset(np.zeros(len(geometry), bool))
        return _augmented(empty, geometry, np.asarray(parts.mean[0]) + noise)

    def seed(self, seed: int) -> tuple[dict, list]:
        """One seed: {(strategy, budget): (width, sd, covered)} and design's chosen settings."""
        settings, largest = self.settings, max(self.settings.budgets)
        rng = np.random.default_rng(1000 + seed)
        initial = self.initial_data(rng)
        sites = self.fit(initial, seed)
        run = DesignRun(self.scene, initial, sites, self.path)
        target = f"tis:{settings.theta_i_deg:g}"
        options = DesignOptions(budget=largest, seed=seed)
        picked = design(run, target, self.grid, options).chosen
        rows_of = {
            "design": _design_rows(picked),
            "random": _subset(self.grid, rng.choice(len(self.grid), largest, replace=False)),
            "article": _article(rng, largest, self.series),
        }
        normals = rng.standard_normal(largest)
        truth_run = DesignRun(self.scene, initial, self.truth, self.path)
        outcomes = {("initial", 0): self.interval(sites)}
        for budget in settings.budgets:
            for name in STRATEGIES[1:]:
                candidates = _subset(rows_of[name], np.arange(budget))
                values = _simulate(truth_run, candidates, self.truth, normals[:budget])
                rows = candidate_measurements(candidates, initial)
                draws = self.fit(_augmented(initial, rows, values), seed + 7)
                outcomes[(name, budget)] = self.interval(draws)
        return outcomes, [(c["theta_i_deg"], c["theta_s_deg"]) for c in picked]


def payoff(
    run_dir: str | Path, settings: PayoffSettings = PayoffSettings(), progress=print
) -> dict:
    """The synthetic experiment (module docstring); widths and coverage per strategy and budget.

    Every strategy of one seed sees the same initial data, the same standard normal deviates
    for its new rows (common random numbers) and the same NUTS keys, so the strategies differ
    by where the rows are, not by luck; each budget's rows extend the smaller budget's.
    """
    start = time.perf_counter()
    experiment = _Experiment(load_design_run(run_dir), settings)
    outcomes, chosen = [], []
    for seed in range(settings.seeds):
        outcome, picked = experiment.seed(seed)
        outcomes.append(outcome)
        chosen.append(picked)
        progress(f"  design pay-off seed {seed + 1}/{settings.seeds}")
    labels = {key: f"{key[0]}:{key[1]}" for key in outcomes[0]}

    def collect(index: int) -> dict[str, list]:
        return {labels[k]: [outcome[k][index] for outcome in outcomes] for k in labels}

    return {
        "true_tis": experiment.true_tis,
        "theta_i_deg": settings.theta_i_deg,
        "budgets": list(settings.budgets),
        "seeds": settings.seeds,
        "initial_rows": len(experiment.geometry),
        "initial_series": settings.initial_series,
        "series": experiment.series,
        "widths": collect(0),
        "sds": collect(1),
        "covered": {k: int(np.sum(v)) for k, v in collect(2).items()},
        "chosen": chosen,
        "seconds": time.perf_counter() - start,
    }


def payoff_rows(result: dict) -> list[list[str]]:
    """Markdown table rows of :func:`payoff`: per budget and strategy the mean 95 % width of
    TIS(θ) [per cent TIS], its ratio to the initial width, and against design the paired
    difference (design minus the strategy, mean ± standard error over seeds) and the number of
    seeds in which design's interval is the narrower."""
    widths = {k: np.asarray(v) for k, v in result["widths"].items()}
    initial = np.mean(widths["initial:0"])
    seeds = result["seeds"]
    names = {"design": "design", "random": "random feasible", "article": "the article's kind"}
    rows = [
        [
            "0",
            "none (initial design)",
            f"{100 * initial:.3f}",
            "1.000",
            "—",
            "—",
            f"{result['covered']['initial:0']}/{seeds}",
        ]
    ]
    for budget in result["budgets"]:
        chosen = widths[f"design:{budget}"]
        for strategy in STRATEGIES[1:]:
            key = f"{strategy}:{budget}"
            paired, narrower = "—", "—"
            if strategy != "design":
                difference = 100 * (chosen - widths[key])
                error = np.std(difference, ddof=1) / np.sqrt(seeds) if seeds > 1 else np.nan
                paired = f"{np.mean(difference):+.3f} ± {error:.3f}"
                narrower = f"{int(np.sum(chosen < widths[key]))}/{seeds}"
            rows.append(
                [
                    str(budget),
                    names[strategy],
                    f"{100 * np.mean(widths[key]):.3f}",
                    f"{np.mean(widths[key]) / initial:.3f}",
                    paired,
                    narrower,
                    f"{result['covered'][key]}/{seeds}",
                ]
            )
    return rows


COMMAND_HEADERS = ["compilation cache", "wall [s]", "design's own seconds", "chosen θi, θs [deg]"]


def command_rows(run_dir: str | Path, scratch: Path) -> list[list[str]]:
    """``brdf-infer design RUN_DIR --target tis:70 --budget 3 --json`` in fresh processes,
    with an empty compilation cache and then the same cache again."""
    rows = []
    argv = ["design", str(run_dir), "--target", "tis:70", "--budget", "3"]
    for state in ("cold", "warm"):
        wall, payload = timed_command(argv, scratch / "cache", scratch / f"design-{state}")
        chosen = ", ".join(
            f"({c['theta_i_deg']:g}, {c['theta_s_deg']:g})" for c in payload["chosen"]
        )
        rows.append([state, f"{wall:.1f}", f"{payload['seconds']:.1f}", chosen])
    return rows


def _first_campaign_scene(scene, folder: Path):
    """The scene with its series-I rows only (the article's first, specular campaign), as a
    scene file of its own in ``folder`` (a design run is tied to its scene's rows)."""
    import csv

    folder.mkdir()
    source = scene.path.parent
    for name in ("lya_tis_reference.csv",):
        (folder / name).write_bytes((source / name).read_bytes())
    with (source / "lya_measurements.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    with (folder / "lya_measurements.csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(row for row in rows if row["series"] == "I")
    (folder / scene.path.name).write_text(scene.path.read_text())
    return load_scene(folder / scene.path.name)


def _reduced_run(scene: Scene, out: Path, quick: bool) -> int:
    """A NUTS run of ``scene`` into ``out`` at the benchmark's reduced settings; its draws."""
    chains, draws = (2, 500) if quick else (4, 1000)
    measurements = scene.load_measurements()
    warmup = 300 if quick else 500
    run_posterior(
        scene, measurements, chains=chains, warmup=warmup, draws=draws, out=out, progress=False
    )
    return chains * draws


def _refits(run_dir: Path, series: str, quick: bool, progress) -> list[list[str]]:
    """Estimate against refit rows, seeds in turn."""
    rows = []
    for seed in range(1 if quick else 2):
        settings = RefitSettings(replicates=2 if quick else 8, seed=seed)
        rows += refit_rows(refit_check(run_dir, "tis:70", series, settings, progress))
    return rows


def _payoff_lines(result: dict) -> list[str]:
    if result["initial_series"] is not None:
        first = (
            f"series {result['series']}'s {result['initial_rows']} measured rows only "
            "(the first campaign: specular geometry), new rows in the same series"
        )
    else:
        first = (
            f"the scene's {result['initial_rows']} measured rows, new rows in series "
            f"{result['series']}"
        )
    return [
        f"Pay-off from {first}: a known truth (the run's posterior medians, true "
        f"TIS({result['theta_i_deg']:g}°) = {100 * result['true_tis']:.2f} %), the initial "
        "data simulated from it, K rows added three ways and every data set refitted by "
        f"NUTS; {result['seeds']} seeds with common random numbers "
        f"({result['seconds']:.0f} s).",
        "",
        markdown_table(HEADERS, payoff_rows(result)),
        "",
    ]


def design_section(quick: bool, progress=print) -> list[str]:
    """The benchmark report's section: the command's time, estimate against refit (several
    seeds, from the bundled scene and from its first campaign alone) and the pay-off experiment
    from both, on reduced NUTS runs made here."""
    scene = load_scene("lya")
    seeds = 2 if quick else 8
    with tempfile.TemporaryDirectory() as folder:
        base, first = Path(folder) / "lya", Path(folder) / "series-I"
        draws = _reduced_run(scene, base, quick)
        refits = _refits(base, "II", quick, progress)
        _reduced_run(_first_campaign_scene(scene, Path(folder) / "scene-I"), first, quick)
        first_refits = _refits(first, "I", quick, progress)
        # from the scene's rows one row changes the width by a few per cent: three times the
        # seeds there to resolve design against random
        results = [
            payoff(base, PayoffSettings(seeds=count, initial_series=initial), progress)
            for initial, count in (("I", seeds), (None, 3 * seeds))
        ]
        progress("  design command, cold and warm ...")
        commands = command_rows(base, Path(folder) / "scratch")
    lines = [
        "## Experimental design (`brdf-infer design`)",
        "",
        f"The command on this section's run ({draws} draws of the bundled scene), "
        "fresh processes, wall time from start to exit:",
        "",
        markdown_table(COMMAND_HEADERS, commands),
        "",
        "Estimate against refit: the expected posterior sd of TIS(70°) after one more row at "
        "the best, median and worst grid candidate, against NUTS refits with that row "
        "simulated from the posterior (8 replicates, 2 × (300 + 300) draws). The sd is in per "
        "cent TIS; the ratio is to today's sd — the estimate's from the run's draws, the "
        "refits' over a refit of the measured rows alone with the same keys (what design "
        "claims; absolute sds also carry the run's own Monte Carlo error of about 2 %). "
        "Seeds in turn, each a row per candidate.",
        "",
        "The bundled scene (42 rows), a new series-II row:",
        "",
        markdown_table(REFIT_HEADERS, refits),
        "",
        "Series I's 24 specular rows alone (the first campaign), a new series-I row:",
        "",
        markdown_table(REFIT_HEADERS, first_refits),
        "",
    ]
    for result in results:
        lines += _payoff_lines(result)
    return lines
