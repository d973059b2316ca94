"""Where to measure next: ``brdf-infer design`` (Bayesian experimental design from a run).

For every candidate setting (:mod:`._candidates`) the expected posterior sd of a target after
one more row there, its ratio to today's sd and the expected information gain, estimated from
the run's own posterior draws by importance reweighting (:mod:`._estimate`); with a budget of
K rows, K settings chosen together, greedily on the joint expected result of the set (each step
adds the candidate that, measured together with those already chosen, leaves the smallest
expected sd — not K times the single best).

The new rows' predictive is their conditional given the measured rows under the scene's own
error model, so the answer depends on the session a row is taken in. By default every new row
is a new session: a reference measurement of its own (Eq. 2; the source's energy fluctuates by
≈ 9 %, Sec. 2), i.e. a calibration factor of its own — one for all new rows of a
series, shared among them and unknown to the measured rows — and rotation settings of its own;
only the sample effect is shared with the measured rows. A row continuing a measured session
(``same_session``) shares that series' calibration factor and, at a θi already measured, its
rotation error with the measured rows. The run must be of the scene (its name and its rows).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer._internal.precision import ensure_float64
from brdf_infer.design._candidates import (
    NEW_SAMPLE,
    REACH_LIMITS,
    Candidates,
    candidate_measurements,
    check_budget,
    design_sample,
    design_series,
    grid_candidates,
    session_scene,
)
from brdf_infer.design._estimate import (
    ESS_FLOOR,
    RowPredictive,
    candidate_outcomes,
    row_predictive,
)
from brdf_infer.errors import BadInputError
from brdf_infer.model import (
    check_family_name,
    family,
    log_brdf_inplane,
    run_family_name,
    tis,
)
from brdf_infer.model.error_model import (
    angle_slopes,
    calibration_groups,
    group_members,
    noise_layout,
)
from brdf_infer.model.params import DPHI_NAME, PARAM_NAMES, Params, with_dphi_scale
from brdf_infer.posterior import (
    NEW_PART_EFFECT,
    SAMPLE_EFFECT,
    build_posterior_model,
    interval95,
    run_measurements,
    run_scene,
    target_log_factor,
)
from brdf_infer.predict.observations import (
    build_observation_model,
    log_reflectance_at,
    predicted_log_reflectance,
)
from brdf_infer.runs.folder import DESIGN_FIGURE, DESIGN_FILE, RunFolder
from brdf_infer.scene import Scene, load_scene
from brdf_infer.scene.design_target import DesignTarget, parse_target
from brdf_infer.scene.settings import DesignOptions
from brdf_infer.tables.measurements import Measurements


@dataclass(frozen=True)
class DesignRun:
    """What the study reads from a run folder and its scene.

    Attributes:
        scene, measurements: the scene of the run and its rows.
        sites: every draw of the run's sites needed by the likelihood (flattened), and each
            draw's sample effects (``sample_effect``, (draws, samples); ``new_part_effect``)
            where the run has them (:mod:`brdf_infer.posterior._targets`).
        path: the run's posterior.nc.
        target: the target of the run's bands (``coating`` for a run before the targets).
        sample_names: the measured samples, in ``sample_effect``'s order.
    """

    scene: Scene
    measurements: Measurements
    sites: dict[str, np.ndarray]
    path: Path
    target: str = "coating"
    sample_names: tuple[str, ...] = ()


def load_design_run(run: str | Path, scene: Scene | str | None = None) -> DesignRun:
    """The run folder's draws and its scene (``scene``: check the run is of this one).

    Raises:
        BadInputError: no readable posterior.nc, a run of another scene or other rows, a run
            of a family other than ``strumik2024``.
    """
    from brdf_infer._internal import arviz as az
    from brdf_infer._internal.outlock import require_complete

    require_complete(run)  # not a folder a writer is writing or left unfinished
    path = RunFolder(run).posterior_file
    if not path.is_file():
        raise BadInputError("no posterior.nc here (run 'brdf-infer run' first)", file=run)
    try:
        idata = az.from_netcdf(path)
    except (OSError, ValueError) as error:
        raise BadInputError(f"cannot read: {error}", file=path) from None
    attrs = idata.posterior.attrs
    name = run_family_name(attrs)
    check_family_name(name, file=path)
    if not family(name).paper_parameters:  # the design's targets are Eq. (7)'s
        raise BadInputError(f"a run of {name}, not of strumik2024", file=path)
    measurements = None
    if scene is None:  # the run's own scene and rows (no measurement file read)
        scene, measurements = run_scene(attrs), run_measurements(idata)
    elif isinstance(scene, str):
        scene = load_scene(scene)
    if attrs.get("scene") != scene.name:
        raise BadInputError(
            f"a run of scene '{attrs.get('scene')}', not of '{scene.name}'", file=path
        )
    if measurements is None:
        measurements = scene.load_measurements()
    observed = np.asarray(idata.observed_data["obs"])
    if observed.shape != (len(measurements),) or not np.allclose(
        observed, np.log(measurements.reflectance)
    ):
        raise BadInputError(f"a run on other rows than scene '{scene.name}' has now", file=path)
    names = [*PARAM_NAMES, DPHI_NAME, "sample_sd", "repeatability", NEW_PART_EFFECT]
    posterior = idata.posterior
    sites = {name: np.asarray(posterior[name]).reshape(-1) for name in names if name in posterior}
    samples: tuple[str, ...] = ()
    if SAMPLE_EFFECT in posterior:
        samples = tuple(str(name) for name in np.asarray(posterior["sample"]))
        sites[SAMPLE_EFFECT] = np.asarray(posterior[SAMPLE_EFFECT]).reshape(-1, len(samples))
    target = str(attrs.get("target", "coating"))
    return DesignRun(scene, measurements, sites, path, target, samples)


def target_values(
    target: DesignTarget, draws: dict[str, np.ndarray], scene: Scene, coating: str = "coating"
) -> np.ndarray:
    """(draws, P) values of the target per draw of ``draws`` (P = 1, or the free parameters
    for ``all``): the products' BRDF and TIS (``[outputs] fold``; each draw's out-of-plane
    width where the run has one) of ``coating``, the sample(s) measured, the coating or a new
    part (:mod:`brdf_infer.posterior._targets`: the BRDF times each draw's e^u; a parameter
    is the coating's)."""
    values = _coating_values(target, draws, scene)
    if target.kind in ("param", "all") or coating == "coating":
        return values
    effects = draws[SAMPLE_EFFECT]
    names = tuple(str(k) for k in range(effects.shape[1]))
    factor = target_log_factor(coating, effects, draws[NEW_PART_EFFECT], names)
    return values * np.exp(factor)[:, None]


def _coating_values(target: DesignTarget, draws: dict[str, np.ndarray], scene: Scene):
    """:func:`target_values` of the coating."""
    params = Params(*(jnp.asarray(draws[name]) for name in PARAM_NAMES))
    fold = scene.outputs.fold
    constants = scene.model.constants
    if DPHI_NAME in draws:
        constants = with_dphi_scale(constants, jnp.asarray(draws[DPHI_NAME]))
    if target.kind == "tis":
        values = tis(jnp.asarray(target.angles_deg[0]), params, fold, constants)
    elif target.kind == "brdf":
        values = jnp.exp(log_brdf_inplane(*target.angles_deg, params, fold, constants))
    elif target.kind == "pi_brdf0":
        values = math.pi * params.brdf0
    elif target.kind == "param":
        values = getattr(params, target.parameter)
    else:
        return np.stack([np.asarray(getattr(params, n)) for n in scene.free_parameters], axis=1)
    return np.asarray(values, float).reshape(-1, 1)


def _shared_column(keys: list, key) -> int:
    """Column of ``key`` among the groups of two or more rows (−1: none, the row is new)."""
    unique = list(dict.fromkeys(keys))
    counts = {k: keys.count(k) for k in unique}
    shared = [k for k in unique if counts[k] > 1]
    return shared.index(key) if key in shared else -1


def _loading_columns(errors, measurements, new, fresh: np.ndarray, columns: int):
    """Where each candidate row loads on the measured rows' shared effects (a column of their
    factor W, or −1: an effect of its own): its sample, its calibration group (−1 in a new
    session, ``fresh``), and its rotation setting; and a new session's calibration groups
    (``fresh_col``: the row's index among ``fresh_groups``, else −1)."""
    samples = list(measurements.sample)
    groups = calibration_groups(errors, measurements)
    sample_shared = group_members(samples)[0].shape[1]
    new_groups = calibration_groups(errors, new) or [None] * len(new)
    sample_col = np.array([_shared_column(samples, s) for s in new.sample])
    calibration_col = np.array(
        [
            -1 if groups is None or is_new else _shared_column(groups, g)
            for g, is_new in zip(new_groups, fresh, strict=True)
        ]
    )
    calibration_col = np.where(calibration_col >= 0, calibration_col + sample_shared, -1)
    # a new session's reference: one calibration factor per new group, shared by its rows
    fresh_groups = list(
        dict.fromkeys(g for g, is_new in zip(new_groups, fresh, strict=True) if is_new)
    )
    if groups is None:  # no calibration in the error model
        fresh_groups = []
    fresh_col = np.array(
        [
            fresh_groups.index(g) if g in fresh_groups and is_new else -1
            for g, is_new in zip(new_groups, fresh, strict=True)
        ]
    )
    # a row continuing a session at a (series, sample, θi) measured shares that setting's
    # rotation error; a new session's settings are its own
    settings = list(
        zip(measurements.series, measurements.sample, measurements.theta_i_deg, strict=True)
    )
    rotation_shared = columns - group_members(settings)[0].shape[1]
    rotation_col = np.array(
        [
            -1 if is_new else _shared_column(settings, key)
            for key, is_new in zip(
                zip(new.series, new.sample, new.theta_i_deg, strict=True), fresh, strict=True
            )
        ]
    )
    rotation_col = np.where(rotation_col >= 0, rotation_col + rotation_shared, -1)
    return sample_col, calibration_col, fresh_col, fresh_groups, rotation_col


def _given_effects(model, effects, measured, sample_sd, new: Measurements):
    """The measured rows' (residual, factor, diagonal) given each draw's sample effects
    ``effects`` (S, samples): the residual less the row's u_j, the samples' columns out and a
    lone row's τ² off its diagonal; and each candidate's shift, its sample's u_j (0 for a
    sample not measured)."""
    residual, factor, diagonal = measured
    names = list(model.sample_names)
    index = np.array([names.index(str(sample)) for sample in model.row_samples])
    noise = model.data.noise
    residual = residual - effects[:, index]
    factor = factor.at[..., : noise.sample_members.shape[-1]].set(0.0)
    diagonal = diagonal - noise.sample_alone[None, :] * sample_sd[:, None] ** 2
    on = np.array([names.index(str(s)) if str(s) in names else -1 for s in new.sample])
    shift = jnp.where(jnp.asarray(on >= 0)[None, :], effects[:, np.maximum(on, 0)], 0.0)
    return residual, factor, diagonal, shift


def predictive(
    run: DesignRun,
    candidates: Candidates,
    draws: dict,
    coating: str = "coating",
    new_sample: bool = False,
) -> RowPredictive:
    """Every draw's conditional predictive of every candidate row (:mod:`._estimate`), each
    row in its session (:attr:`Candidates.session`; None: its series' measured one). A new
    session's calibration factor is one more shared effect, a column of the loading that the
    measured rows do not load on; so is a new sample's effect (``new_sample``: every candidate
    on one physical sample not yet measured, :data:`NEW_SAMPLE`).

    For the ``measured`` target the draws carry each measured sample's effect u_j
    (``sample_effect``), and the rows are conditioned on it: a measured row's residual less
    its u_j, the samples' columns of the factor (and a lone row's τ²) out, a candidate's mean
    plus its sample's u_j; the importance weights are then those of the joint draw (θ, u).
    """
    scene, measurements = run.scene, run.measurements
    model = build_posterior_model(scene, measurements)
    parts = model.draw_parts(draws)
    residual = model.data.rows.log_reflectance[None, :] - parts.mean
    factor, diagonal = parts.factor, parts.diagonal
    count = residual.shape[0]
    errors = scene.errors
    sample_sd = jnp.asarray(draws.get("sample_sd", np.full(count, errors.stated_sample_sd)))
    new = candidate_measurements(candidates, measurements, new_sample)
    known = coating == "measured"
    shift = jnp.zeros((count, len(new)))
    if known:
        residual, factor, diagonal, shift = _given_effects(
            model, jnp.asarray(draws[SAMPLE_EFFECT]), (residual, factor, diagonal), sample_sd, new
        )
    rows = build_observation_model(scene, new).data
    layout = noise_layout(errors, new)
    columns = parts.factor.shape[2]
    sample_col, calibration_col, fresh_col, fresh_groups, rotation_col = _loading_columns(
        errors, measurements, new, candidates.sessions() == "new", columns
    )
    fresh_one_hot = jnp.asarray(fresh_col[:, None] == np.arange(len(fresh_groups))[None, :], float)
    one_hot_sample = jnp.asarray(sample_col[:, None] == np.arange(columns)[None, :], float)
    one_hot_cal = jnp.asarray(calibration_col[:, None] == np.arange(columns)[None, :], float)
    one_hot_rotation = jnp.asarray(rotation_col[:, None] == np.arange(columns)[None, :], float)
    rotation_new = jnp.asarray(rotation_col < 0, float)
    # a candidate's own sample variance: where its sample is neither a column of the measured
    # rows (a sample of one row) nor known (the measured target) nor the new sample's column
    own_sample = jnp.asarray((sample_col < 0) & (not known) & (not new_sample), float)
    fold, constants = scene.model.fold, scene.model.constants
    params = Params(*(jnp.asarray(draws[name]) for name in PARAM_NAMES))
    if "repeatability" in draws:
        repeatability = jnp.asarray(draws["repeatability"])
    else:  # fixed by the scene (learned: a site of the run)
        fixed = float(errors.repeatability) if errors.model == "generative" else 0.0
        repeatability = jnp.full(count, fixed)
    calibration = layout.calibration_sd  # per new row, as the rotation and camera scales
    # each draw's own out-of-plane width (Eq. 8 scaled): an out-of-plane candidate's
    # prediction then carries Δφ's uncertainty, and its outcome can teach it
    dphi_scale = jnp.asarray(draws.get(DPHI_NAME, np.ones(count)))

    def one(p, scale, tau, rep, res, factor, diagonal, shift):
        widths = with_dphi_scale(constants, scale)
        mean = predicted_log_reflectance(p, rows, fold, widths) + shift
        if errors.angles_on:
            g_rot, g_cam = angle_slopes(
                lambda ti, ts: log_reflectance_at(ti, ts, p, fold, widths, rows),
                rows.theta_i_deg,
                rows.theta_s_deg,
                layout.theta_s_per_rotation,
            )
        else:
            g_rot = g_cam = jnp.zeros_like(mean)
        rotation = g_rot * layout.rotation_deg
        loading = (
            (0.0 if known else tau) * one_hot_sample
            + calibration[:, None] * one_hot_cal
            + rotation[:, None] * one_hot_rotation
        )
        own = (
            layout.sigma_row**2
            + rep**2
            + (g_cam * layout.camera_deg) ** 2
            + rotation_new * rotation**2
            + own_sample * tau**2
            + jnp.asarray((calibration_col < 0) & (fresh_col < 0), float) * calibration**2
        )
        given = row_predictive(res, factor, diagonal, mean, loading, own)
        fresh = [calibration[:, None] * fresh_one_hot] if fresh_groups else []
        if new_sample:  # the new sample's effect, shared by every candidate
            fresh.append(tau * jnp.ones((mean.shape[0], 1)))
        if not fresh:
            return given
        return given._replace(loading=jnp.concatenate([given.loading, *fresh], axis=1))

    program = jax.jit(jax.vmap(one))
    return program(params, dphi_scale, sample_sd, repeatability, residual, factor, diagonal, shift)


@dataclass(frozen=True)
class DesignResult:
    """The study's answer (:meth:`as_json` is the JSON contract of ``brdf-infer design``)."""

    target: DesignTarget
    current: dict[str, Any]
    candidates: list[dict[str, Any]]
    chosen: list[dict[str, Any]]
    budget: int
    seconds: float
    measured: list[dict[str, Any]]
    options: DesignOptions
    reach: dict[str, Any]
    left_out: dict[str, int] | None
    same_session: str | None
    coating: str = "coating"
    new_sample: bool = False

    def as_json(self) -> dict[str, Any]:
        return {
            "target": self.target.name,
            "target_label": self.target.label,
            "for": self.coating,  # the sample(s) measured, the coating or a new part
            "new_sample": self.new_sample,  # the rows on a physical sample not yet measured
            "current": self.current,
            "candidates": self.candidates,
            "chosen": self.chosen,
            "budget": self.budget,
            "seconds": self.seconds,
            "draws": self.options.draws,
            "simulations": self.options.simulations,
            "ess_floor": ESS_FLOOR,
            "same_session": self.same_session,
            "reach": self.reach,
            "left_out": self.left_out,
            "measured": self.measured,
        }


def _entry(candidates: Candidates, index: int, outcome) -> dict:
    """A candidate's JSON entry (the target standardised to today's sd 1): the importance
    estimate, the linear one where the ESS collapses."""
    ess = float(outcome.ess[index])
    weighted = ess >= ESS_FLOOR
    variance = np.asarray(
        outcome.variance_weighted[index] if weighted else outcome.variance_linear[index]
    )
    # E_y[Var(T | D, y)] <= Var(T | D) (total variance): a ratio above 1 is Monte Carlo noise
    ratios = np.sqrt(np.minimum(variance, 1.0))
    ratio = float(np.exp(np.mean(np.log(np.maximum(ratios, 1e-300)))))  # geometric mean
    return {
        **candidates.row(index),
        "expected_sd": float(ratios[0]) if len(variance) == 1 else ratio,
        "sd_ratio": ratio,
        "eig_nats": float(outcome.eig[index]),
        "ess": ess,
        "method": "importance" if weighted else "linear",
    }


def design(
    run: DesignRun,
    target: str | DesignTarget = "tis:70",
    candidates: Candidates | None = None,
    options: DesignOptions | None = None,
    series: str | None = None,
    same_session: str | None = None,
    aperture: tuple[float, float] | None = None,
    coating: str | None = None,
    new_sample: bool = False,
) -> DesignResult:
    """Where to measure next for ``target`` (module docstring).

    Args:
        run: the run folder's draws and scene (:func:`load_design_run`).
        target: a target string (:mod:`brdf_infer.scene.design_target`) or a parsed one.
        candidates: the settings to consider (default: the reachable settings of the scene's
            ``[design]`` grid in the design series).
        options: draws, simulations, budget and seed (default :class:`DesignOptions`).
        series: the series new grid rows are taken in (default: ``same_session``, else
            ``[design] series``, else the series with the most rows); one without rows is a
            new series.
        same_session: the measured series whose session its new rows continue (default
            ``[design] same_session``; None: every new row is a new session).
        aperture: (diameter, distance) [mm] of a new series (default its ``[series.NAME]``).
        coating: whose target: ``measured``, ``coating`` or ``new_part``
            (:mod:`brdf_infer.posterior._targets`; None: the run's); a parameter is the
            coating's.
        new_sample: the new rows are taken on one physical sample not yet measured (is
            another sample worth more than another angle?).

    Raises:
        BadInputError: ``same_session`` not a measured series, a new series without an
            aperture, a sample's or new part's target of a parameter or of a run written
            before the targets.
    """
    ensure_float64()
    start = time.perf_counter()
    options = DesignOptions() if options is None else options
    target = parse_target(target) if isinstance(target, str) else target
    measurements = run.measurements
    same_session = same_session or run.scene.design.same_session
    name = design_series(run.scene, measurements, series, same_session, aperture)
    run = replace(run, scene=session_scene(run.scene, name, aperture))
    scene = run.scene
    if candidates is None:
        candidates = grid_candidates(scene.design, name)
    candidates = candidates.in_sessions(same_session).without_measured(measurements)
    check_budget(options.budget, len(candidates))
    total = len(run.sites["brdf0"])
    keep = np.unique(np.linspace(0, total - 1, min(options.draws, total)).round().astype(int))
    draws = {name: values[keep] for name, values in run.sites.items()}
    coating = design_coating(target, run, coating)
    values = target_values(target, draws, scene, coating)
    scale = np.std(values, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    row_predictive_ = predictive(run, candidates, draws, coating, new_sample)
    chosen, single = _greedy(
        row_predictive_, candidates, target, jnp.asarray(values / scale), float(scale[0]), options
    )
    samples = {name: design_sample(measurements, name) for name in set(candidates.series)}
    for entry in [*chosen, *single]:  # the sample a row is to be taken on
        entry["sample"] = NEW_SAMPLE if new_sample else samples[entry["series"]]
    current = _current(target, run, scene, scale, coating)
    rows = measurements.series, measurements.theta_i_deg, measurements.theta_s_deg
    measured = [
        {"series": str(s), "theta_i_deg": float(i), "theta_s_deg": float(t)}
        for s, i, t in zip(*rows, strict=True)
    ]
    return DesignResult(
        target=target,
        current=current,
        candidates=single,
        chosen=chosen,
        budget=options.budget,
        seconds=time.perf_counter() - start,
        measured=measured,
        options=options,
        reach={
            name: list(value) if isinstance(value, tuple) else value
            for name, value in ((n, getattr(scene.design, n)) for n in REACH_LIMITS)
        },
        left_out=candidates.left_out,
        same_session=same_session,
        coating=coating,
        new_sample=new_sample,
    )


def design_coating(target: DesignTarget, run: DesignRun, coating: str | None) -> str:
    """Whose ``target`` a design shrinks: ``coating`` as asked, else the run's target; a
    parameter is always the coating's.

    Raises:
        BadInputError: a parameter asked of a sample or a new part, or a sample's or new
            part's target of a run written before the targets.
    """
    if target.kind in ("param", "all"):
        if coating not in (None, "coating"):
            raise BadInputError(
                f"{target.label} is a parameter of the coating, not of {coating}", field="coating"
            )
        return "coating"
    chosen = coating or run.target
    if chosen != "coating" and SAMPLE_EFFECT not in run.sites:
        raise BadInputError(
            "a run written before the measured and new-part targets: rerun its posterior",
            file=run.path,
            field="coating",
        )
    return chosen


def _greedy(
    row_predictive_: RowPredictive,
    candidates: Candidates,
    target: DesignTarget,
    standardised: jnp.ndarray,
    scale: float,
    options: DesignOptions,
) -> tuple[list[dict], list[dict]]:
    """The rows chosen one after another, each the best given those before it (with its
    ``step``), and every candidate's entry alone, best first; ``standardised``: the target's
    values per draw over ``scale`` (its sd), the entries back in its units."""
    count = standardised.shape[0]
    key_simulate, key_draws = jax.random.split(jax.random.PRNGKey(options.seed))
    # one column of outcomes per step, each from its own key: a larger budget extends a smaller
    # one's picks instead of drawing them anew
    standard = jnp.stack(
        [
            jax.random.normal(jax.random.fold_in(key_simulate, step), (options.simulations,))
            for step in range(options.budget)
        ],
        axis=1,
    )
    simulated = (jnp.arange(options.simulations) * count) // options.simulations
    simulated = (simulated + jax.random.randint(key_draws, (), 0, count)) % count
    chosen_index: list[int] = []
    chosen, single = [], []
    for step in range(options.budget):
        outcome = candidate_outcomes(
            row_predictive_,
            jnp.asarray(chosen_index, int),
            standardised,
            standard[:, : step + 1],
            simulated,
        )
        entries = [_entry(candidates, i, outcome) for i in range(len(candidates))]
        for entry in entries:  # back to the target's units (standardised above)
            if target.kind != "all":
                entry["expected_sd"] *= scale
        order = _order(entries, target)
        if step == 0:
            single = [entries[i] for i in order]
        # one row per setting (a table holds one; a repeat goes on another sample or session)
        best = next(i for i in order if i not in chosen_index)
        chosen_index.append(best)
        chosen.append({**entries[best], "step": step + 1})
    return chosen, single


def _order(entries: list[dict], target: DesignTarget) -> list[int]:
    """Candidates best first: by expected sd (by expected information gain for ``all``)."""
    if target.kind == "all":
        return sorted(range(len(entries)), key=lambda i: -entries[i]["eig_nats"])
    return sorted(range(len(entries)), key=lambda i: entries[i]["expected_sd"])


def _current(
    target: DesignTarget, run: DesignRun, scene: Scene, scale, coating: str
) -> dict[str, Any]:
    """Today's median, 95 % interval and sd of the target over every draw of the run (sd: over
    the thinned draws the expectation uses, so that the ratio compares like with like)."""
    if target.kind == "all":
        return {"median": None, "lo95": None, "hi95": None, "sd": 1.0}
    values = target_values(target, run.sites, scene, coating)[:, 0]
    return {**interval95(values), "sd": float(scale[0])}


def write_design(out: str | Path, result: DesignResult) -> list[Path]:
    """design.json and the map design.png into ``out``, atomically."""
    from brdf_infer.design._figure import design_figure

    folder = RunFolder(out)
    payload = result.as_json()
    return [
        folder.write_json(DESIGN_FILE, payload),
        folder.write_bytes(DESIGN_FIGURE, design_figure(payload)),
    ]
