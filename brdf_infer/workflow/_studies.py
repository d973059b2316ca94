"""The main job's steps (:func:`brdf_infer.workflow.run`): the job and its numbered progress
lines, and the studies a scene asks for, one function each."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from brdf_infer.scene import Scene, Studies
from brdf_infer.scene.settings import RunSettings
from brdf_infer.tables.measurements import Measurements


@dataclass
class Job:
    """One main job (:func:`brdf_infer.workflow.run`): its inputs, and its numbered steps
    (``[k/n] ...``)."""

    scene: Scene
    measurements: Measurements
    out: Path
    settings: RunSettings
    progress: Callable[[str], None]
    name: str  # the model family
    studies: Studies
    paper_parameters: bool  # the family's parameters are Eq. (7)'s: its studies run
    steps: int
    _numbers: Iterator[int] = field(init=False)

    def __post_init__(self) -> None:
        self._numbers = iter(range(1, self.steps + 1))

    def step(self, text: str) -> None:
        """The next step's progress line."""
        self.progress(f"[{next(self._numbers)}/{self.steps}] {text}")


def error_model_posterior(
    job: Job, error_model: str, options: dict[str, Any], forced: list[str]
) -> None:
    """Study: the posterior under another error model, into ``variants/<error model>``."""
    from brdf_infer.posterior import run_posterior
    from brdf_infer.runs.folder import RunFolder

    job.step(f"NUTS posterior with the {error_model} error model")
    run_posterior(
        job.scene,
        job.measurements,
        error_model=error_model,
        out=RunFolder(job.out).variant(error_model).path,
        forced=forced,
        refit=False,  # a study's posterior: its width is the main run's business
        **options,
    )


def instrument_study(job: Job, instruments: list[str], options: dict[str, Any], posterior):
    """Study: the posteriors under other instrument models, side by side."""
    from brdf_infer.runs.folder import INSTRUMENT_FILE, RunFolder
    from brdf_infer.studies.instrument_comparison import compare_instruments

    scene, out = job.scene, job.out
    job.step("instrument models: posteriors side by side")
    RunFolder(out).write_json(
        INSTRUMENT_FILE,
        compare_instruments(
            scene,
            job.measurements,
            out,
            options,
            instruments=[scene.instrument.model, *instruments],
            done={scene.instrument.model: (out, posterior)},
            progress=job.progress,
        ),
    )


def compare_study(job: Job) -> dict[str, Any]:
    """Study: the model families ranked by PSIS-LOO."""
    from brdf_infer.report import write_comparison
    from brdf_infer.studies.compare import compare_families

    studies = job.studies
    job.step(f"model comparison by PSIS-LOO: {', '.join(studies.compare)}")
    result = compare_families(job.scene, job.measurements, list(studies.compare))
    write_comparison(job.out, result)
    return result.as_json()


def sensitivity_study(job: Job) -> None:
    """Study: the sensitivity to the error model's assumptions."""
    from brdf_infer.report import write_sensitivity
    from brdf_infer.studies.sensitivity import SensitivitySettings, sensitivity

    job.step("sensitivity to the error-model assumptions")
    write_sensitivity(
        job.out,
        sensitivity(
            job.scene, job.measurements, settings=SensitivitySettings(seed=job.settings.seed)
        ),
    )


def design_study(job: Job) -> None:
    """Study: where to measure next for the design target."""
    from brdf_infer.design import DesignOptions, design, load_design_run, write_design

    scene, out, studies = job.scene, job.out, job.studies
    job.step(f"where to measure next for {studies.design}")
    options = DesignOptions(budget=scene.design.budget, seed=job.settings.seed)
    write_design(out, design(load_design_run(out, scene), studies.design, options=options))
