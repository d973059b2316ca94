"""Scenes of a batch: the sources to load, and the structure key that groups them."""

from __future__ import annotations

import dataclasses
import glob
import hashlib
import json
from typing import Any

import jax
import numpy as np

from brdf_infer.posterior import (
    FlatPotential,
    model_name,
    paddable,
    padded_signature,
)


def expand_sources(patterns: list[str]) -> list[str]:
    """Scene names and TOML paths from names, paths and glob patterns (sorted per pattern;
    a pattern that matches nothing is kept, so that loading it reports it)."""
    sources: list[str] = []
    for pattern in patterns:
        matches = sorted(glob.glob(pattern)) if glob.has_magic(pattern) else []
        sources += matches or [pattern]
    return list(dict.fromkeys(sources))


def structure_key(model) -> str:
    """What must agree for two scenes to share one compiled program: the family, the model's
    options (error model, priors, folding and constants, free parameters, reparametrisation)
    and the data's tree structure and shapes — the row count and the number of samples,
    calibration groups and rotation settings left out where the data can be padded to one shape
    (:func:`brdf_infer.posterior._padding.paddable`)."""
    scene = model.scene
    options: dict[str, Any] = {
        "family": model_name(model),
        "errors": scene.errors.describe(),
        "fold": scene.model.fold,
        "constants": scene.model.constants._asdict(),
        "priors": {k: dataclasses.asdict(v) for k, v in scene.priors.items()},
        "free": list(scene.free_parameters),
        "reparametrised": model.whiten,
    }
    if paddable(model):
        options["padded"] = padded_signature(model.data)
    else:
        leaves, tree = jax.tree_util.tree_flatten(model.data)
        options["tree"] = str(tree)
        options["shapes"] = [(tuple(np.shape(x)), str(np.asarray(x).dtype)) for x in leaves]
    return hashlib.sha256(json.dumps(options, sort_keys=True, default=str).encode()).hexdigest()


def _site_shapes(model, data) -> dict[str, tuple]:
    """The shape of every site of one draw of ``model`` on ``data`` (traced, not run)."""
    flat = FlatPotential(model)
    shapes = jax.eval_shape(flat.constrain, jax.ShapeDtypeStruct((flat.dimension,), float), data)
    return {name: tuple(leaf.shape) for name, leaf in shapes.items()}
