"""Options several commands share (``--force``, ``--model``, ``--instrument``, ``--fold``),
their checks before any work, and the scene they read."""

from __future__ import annotations

import argparse
import importlib

import numpy as np

from brdf_infer.cli._common import progress
from brdf_infer.errors import BadInputError

# where each registry of names lives (module, attribute): read only when a help text is printed
ERROR_MODEL_REGISTRY = ("brdf_infer.model.error_model", "ERROR_MODELS")
INSTRUMENT_REGISTRY = ("brdf_infer.instrument", "INSTRUMENT_MODELS")
FAMILY_REGISTRY = ("brdf_infer.model", "FAMILY_NAMES")


class KnownNames:
    """The names of a registry, looked up when ``--help`` is printed: the registries live in
    modules that import JAX and NumPyro, which building the parser does not."""

    def __init__(self, registry: tuple[str, str]) -> None:
        self.registry = registry

    def __str__(self) -> str:
        module, attribute = self.registry
        return ", ".join(getattr(importlib.import_module(module), attribute))


def with_known_names(action: argparse.Action, registry: tuple[str, str]) -> argparse.Action:
    """``action`` whose help text may say ``%(known)s``: the registry's names, comma-separated
    (argparse fills a help text's ``%(NAME)s`` from the action's attributes)."""
    action.known = KnownNames(registry)
    return action


def add_force_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--force",
        action="store_true",
        help="go on past a failed plausibility check (values that look like percent, angles "
        "that look like radians, a fit whose pi*BRDF0 or TIS exceeds 1); the verdict then "
        "names it",
    )


def add_model_argument(parser: argparse.ArgumentParser, auto: bool = False) -> None:
    """``--model FAMILY``; with ``auto`` also ``--model auto`` (the family PSIS-LOO ranks
    first, :data:`brdf_infer.scene.settings.AUTO_FAMILIES`)."""
    choose = (
        "; auto: the family PSIS-LOO ranks first among strumik2024, abg, lambertian and "
        "lambertian+abg"
        if auto
        else ""
    )
    action = parser.add_argument(
        "--model",
        help=f"model family: %(known)s (default: the scene's [model] family{choose})",
    )
    with_known_names(action, FAMILY_REGISTRY)


def add_instrument_argument(parser: argparse.ArgumentParser) -> None:
    action = parser.add_argument(
        "--instrument",
        help="what a raw reflectance is, one of %(known)s: point is Eq. 6, aperture dPs/Pi "
        "through the detector aperture, image Eq. 2 over the signal square (default: the "
        "scene's [instrument])",
    )
    with_known_names(action, INSTRUMENT_REGISTRY)


def add_fold_arguments(parser: argparse.ArgumentParser, default: str) -> None:
    """``--fold`` and ``--no-fold`` into ``args.fold`` (True, False; None when neither is
    given); ``default`` says in the help what neither means.

    Products default to the physical BRDF (no folding, the conservative choice for a
    stray-light budget); a posterior run's products follow its scene's ``[model] fold``. The
    article's Table 3 comparison folds explicitly with ``--fold``. ``--no-fold`` stays
    accepted (scripts use it).
    """
    group = parser.add_mutually_exclusive_group()
    group.add_argument(
        "--fold",
        dest="fold",
        action="store_const",
        const=True,
        default=None,
        help="include Eq. (10)'s folding, a measurement artefact (the article's Table 3 does)",
    )
    group.add_argument(
        "--no-fold",
        dest="fold",
        action="store_const",
        const=False,
        help=f"leave Eq. (10) out: the physical BRDF (default: {default})",
    )


def chosen_fold(requested: bool | None, default: bool = False) -> bool:
    """The fold switch: ``requested`` on the command line, else ``default`` (a run's own)."""
    return default if requested is None else requested


def folded_family(member, requested: bool | None):
    """A run's family with ``--fold``/``--no-fold`` applied (None: the run's own switch).

    Raises:
        BadInputError: ``--fold`` for a family without Eq. (10).
    """
    if requested is None:
        return member
    try:
        return member.with_fold(requested)
    except ValueError:
        raise BadInputError(f"a run of {member.name} has no Eq. (10)", field="--fold") from None


def add_target_argument(parser: argparse.ArgumentParser, default: str) -> None:
    """``--target``: which coating the bands and products describe (``default`` says in the
    help what leaving it out means)."""
    from brdf_infer.scene import TARGETS

    parser.add_argument(
        "--target",
        choices=TARGETS,
        default=None,
        help="the sample(s) measured, the coating (their population mean) or a new, "
        f"unmeasured part (default: {default})",
    )


def add_run_target_arguments(parser: argparse.ArgumentParser) -> None:
    """``--target`` and ``--sample`` of a command that reads a posterior run (``--run``)."""
    add_target_argument(parser, "a run: the target of its bands")
    parser.add_argument(
        "--sample", help="with --target measured: one measured sample, by name (a run)"
    )


def checked_run_target(args: argparse.Namespace) -> None:
    """``--target``/``--sample`` name what a posterior run describes: they need ``--run``,
    and ``--sample`` the measured target.

    Raises:
        BadInputError: either without ``--run``, or ``--sample`` with another target.
    """
    if args.run is None and (args.target is not None or args.sample is not None):
        field = "--target" if args.target is not None else "--sample"
        raise BadInputError("a target is of a posterior run (--run)", field=field)
    if args.sample is not None and args.target not in (None, "measured"):
        raise BadInputError("a sample is named for the measured target only", field="--sample")


def add_product_switches(parser: argparse.ArgumentParser) -> None:
    """A run's switches of what its products describe, each overriding its scene key:
    ``--target`` (``[outputs] target``), and the two Eq. (10) switches, ``--fold``/``--no-fold``
    the products' (``[outputs] fold``: bands, TIS, maps, exports) and
    ``--likelihood-fold``/``--no-likelihood-fold`` what the instrument measured (``[model]
    fold``: the likelihood's predictions)."""
    add_target_argument(
        parser, "the scene's [outputs] target; auto: measured for one sample, else coating"
    )
    add_fold_arguments(parser, "the scene's [outputs] fold, false unless set")
    group = parser.add_mutually_exclusive_group()
    group.add_argument(
        "--likelihood-fold",
        dest="likelihood_fold",
        action="store_const",
        const=True,
        default=None,
        help="the instrument's readings fold at forward grazing angles: Eq. (10) in the "
        "likelihood (default: the scene's [model] fold)",
    )
    group.add_argument(
        "--no-likelihood-fold",
        dest="likelihood_fold",
        action="store_const",
        const=False,
        help="Eq. (10) left out of the likelihood",
    )


def with_product_switches(scene, args: argparse.Namespace):
    """``scene`` with :func:`add_product_switches`' options applied (None leaves a key as
    is)."""
    from dataclasses import replace

    if args.target is not None:
        scene = replace(scene, outputs=replace(scene.outputs, target=args.target))
    if args.fold is not None:
        scene = replace(scene, outputs=replace(scene.outputs, fold=args.fold))
    if args.likelihood_fold is not None:
        scene = replace(scene, model=replace(scene.model, fold=args.likelihood_fold))
    return scene


def checked_instrument(name: str | None) -> None:
    """``--instrument``: a known instrument model (checked before the scene is read)."""
    from brdf_infer.instrument import INSTRUMENT_MODELS

    if name is not None and name not in INSTRUMENT_MODELS:
        raise BadInputError(
            f"unknown instrument model {name!r} (known: {', '.join(INSTRUMENT_MODELS)})",
            field="--instrument",
        )


def scene_and_measurements(name: str, instrument: str | None = None, force: bool | None = None):
    """The scene (every file it names checked; predicting through ``instrument`` when given)
    and its rows, checked for plausibility (:mod:`brdf_infer.verdict.plausibility`): a failed check
    stops the command unless ``force`` (:func:`forced` then reports it); a command without
    ``--force`` (``force=None``) only warns. Other warnings on stderr."""
    from brdf_infer.scene import check_instrument, load_scene
    from brdf_infer.verdict.plausibility import (
        measurement_checks,
        measurement_warnings,
        require_plausible,
    )

    checked_instrument(instrument)
    scene = load_scene(name)
    if instrument is not None:
        scene = check_instrument(scene, instrument)
    measurements = scene.load_measurements()
    implausible = measurement_checks(scene, measurements)
    if force is None:
        warnings = [found.message for found in implausible]
    else:
        require_plausible(implausible, force)
        warnings = []
    for warning in warnings + measurement_warnings(measurements):
        progress(f"warning: {warning}")
    return scene, measurements


def forced(scene, measurements) -> list[str]:
    """The input checks a ``--force`` command goes past, one line each (also on stderr)."""
    from brdf_infer.verdict.plausibility import measurement_checks

    lines = [found.record for found in measurement_checks(scene, measurements)]
    for line in lines:
        progress(f"warning: forced past a plausibility check: {line}")
    return lines


def angles(values, option: str, low: float, high: float, upper_open: bool = False) -> np.ndarray:
    """``values`` [deg] as an array, each checked to lie in [low, high] (or [low, high))."""
    array = np.asarray(values, dtype=float)
    bad = ~np.isfinite(array) | (array < low) | ((array >= high) if upper_open else (array > high))
    if bad.any():
        bracket = ")" if upper_open else "]"
        raise BadInputError(
            f"{array[bad][0]:g} deg is outside [{low:g}, {high:g}{bracket}", field=option
        )
    return array
