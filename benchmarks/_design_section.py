"""The benchmark report's section on ``brdf-infer design``: the command's time, its estimate
against refits of independently simulated data, and the sequential pay-off study."""

from __future__ import annotations

import tempfile
from pathlib import Path

from benchmarks._design import HEADERS as REFIT_HEADERS
from benchmarks._design import RefitSettings, rank_line, refit_check, refit_rows
from benchmarks._design_payoff import (
    HEADERS as PAYOFF_HEADERS,
)
from benchmarks._design_payoff import (
    PayoffSettings,
    payoff,
    payoff_figure,
    payoff_rows,
)
from benchmarks._tables import markdown_table, timed_command
from brdf_infer._internal.atomic import atomic_write_bytes
from brdf_infer.posterior import run_posterior
from brdf_infer.scene import Scene, load_scene

COMMAND_HEADERS = [
    "command",
    "compilation cache",
    "wall [s]",
    "design's own seconds",
    "chosen θi, θs [deg] (session)",
]
COMMANDS = (
    ("--budget 3", ["--budget", "3"], ("cold", "warm")),
    ("--budget 8", ["--budget", "8"], ("warm",)),
    ("--budget 3 --same-session II", ["--budget", "3", "--same-session", "II"], ("warm",)),
)


def command_rows(run_dir: str | Path, scratch: Path) -> list[list[str]]:
    """``brdf-infer design RUN_DIR --target tis:70 …`` in fresh processes: ``--budget 3`` with
    an empty compilation cache and again with the same cache, then ``--budget 8`` and
    ``--same-session II`` warm."""
    rows = []
    for label, options, states in COMMANDS:
        for state in states:
            argv = ["design", str(run_dir), "--target", "tis:70", *options]
            out = scratch / f"design-{label.replace(' ', '')}-{state}"
            wall, payload = timed_command(argv, scratch / "cache", out)
            chosen = ", ".join(
                f"({c['theta_i_deg']:g}, {c['theta_s_deg']:g}) {c['session']}"
                for c in payload["chosen"]
            )
            rows.append([label, state, f"{wall:.1f}", f"{payload['seconds']:.1f}", chosen])
    return rows


def _reduced_run(scene: Scene, out: Path, quick: bool) -> int:
    """A NUTS run of ``scene`` into ``out`` at the benchmark's reduced settings; its draws."""
    chains, draws, warmup = (2, 500, 300) if quick else (4, 1000, 500)
    run_posterior(
        scene,
        scene.load_measurements(),
        chains=chains,
        warmup=warmup,
        draws=draws,
        out=out,
        progress=False,
    )
    return chains * draws


def _refit_lines(result: dict, label: str) -> list[str]:
    return [
        f"{label} ({result['initial_rows']} rows, {result['seconds']:.0f} s):",
        "",
        markdown_table(REFIT_HEADERS, refit_rows(result)),
        "",
        rank_line(result),
        "",
    ]


def command_section(quick: bool, progress=print) -> list[str]:
    """The section on the command's wall time (its own, so that it can be measured again on a
    quiet machine without the studies)."""
    with tempfile.TemporaryDirectory() as folder:
        base = Path(folder) / "lya"
        draws = _reduced_run(load_scene("lya"), base, quick)
        progress("  design command, cold and warm ...")
        commands = command_rows(base, Path(folder) / "scratch")
    return [
        "## Experimental design: the command's time",
        "",
        f"`brdf-infer design RUN --target tis:70` on a run of the bundled scene ({draws} draws; "
        "design thins to 1000), fresh processes, wall time from start to exit; every chosen "
        "row in a new session unless `--same-session` says otherwise:",
        "",
        markdown_table(COMMAND_HEADERS, commands),
        "",
    ]


def design_section(quick: bool, figure: Path, progress=print) -> list[str]:
    """The section on design's estimates and pay-off (module docstring); the pay-off figure
    written to ``figure``."""
    scene = load_scene("lya")
    replicates = 2 if quick else 8
    settings = PayoffSettings(seeds=3, rounds=2) if quick else PayoffSettings()
    with tempfile.TemporaryDirectory() as folder:
        base = Path(folder) / "lya"
        _reduced_run(scene, base, quick)
        refits = [
            refit_check(base, "tis:70", RefitSettings(replicates, initial_series=s), progress)
            for s in (None, "I")
        ]
        study = payoff(base, settings, progress)
    atomic_write_bytes(figure, payoff_figure(study))
    fit = f"{settings.chains} × ({settings.warmup} + {settings.draws}) draws"
    return [
        "## Experimental design (`brdf-infer design`)",
        "",
        "Estimate against refit, from an independent simulation: per replicate a truth drawn "
        "from the bundled posterior, a virtual lab "
        "(`brdf_infer.studies.synthetic.SyntheticLab`: every "
        "effect drawn term by term, the angle errors moving the angles) measures the initial "
        "rows and then the candidate's row in a new session; NUTS fits both data sets with the "
        f"same keys ({fit}); design estimates the sd ratio of TIS(70°) from the replicate's "
        "posterior of the initial rows. Candidates: design's best, median and worst grid "
        "setting on the run. ± MC: the spread over replicates / √replicates.",
        "",
        *_refit_lines(refits[0], "The bundled scene's geometry"),
        *_refit_lines(refits[1], "Series I's specular rows alone (the first campaign)"),
        f"Pay-off over several rounds: {study['seeds']} truths from the bundled posterior; "
        f"initial data series {study['initial_series']}'s {study['initial_rows']} specular "
        f"rows measured by the lab; {len(study['rows'])} rounds of "
        f"{study['rows'][0]} rows, each round a new session with series {study['series']}'s "
        "set-up, chosen by design, at random among the reachable grid settings, or by the "
        "article's plan (θi 45°, 75°, 80° in turn, δ = 0, ∓5°, ∓10°, ∓15°), each strategy's "
        f"data refitted by NUTS ({fit}) after every round; common random numbers "
        f"({study['seconds']:.0f} s).",
        "",
        markdown_table(PAYOFF_HEADERS, payoff_rows(study)),
        "",
        f"![Sequential design study]({figure.name})",
        "",
    ]
