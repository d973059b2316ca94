"""Data sets of unequal size padded to one shape, so that one compiled program runs them all.

A batch of scenes (``brdf-infer batch``) compiles one NUTS program per model structure and
data shape. Scenes that differ only in their number of rows or in the number of their
physical samples, calibration groups or rotation settings are padded to the largest of each in their
group:

* a padding row carries ``mask`` 0, which removes it from the likelihood and from the
  whitening regression exactly (:mod:`brdf_infer.posterior._likelihood`); its values are only
  kept finite and harmless: the first row's geometry (valid angles, the first row's
  instrument kernel and out-of-plane azimuth), σ 1, ln R 0, ln Ω 0, and no membership in
  any sample, calibration group or rotation setting;
* a padding member column (a sample, calibration group or rotation setting that no row
  belongs to) is all zero: a zero column of W adds exactly nothing to the low-rank normal's
  log density (its capacitance gains an identity row and column) and nothing to the whitening
  regression.

Every model site stays of the same shape (the parameters are scalars) unless the model
samples per-row or per-setting variables (``angle_method = "latent"``): such scenes are not
padded (:func:`paddable` is False) and share a program only with scenes of their exact shape.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from brdf_infer.model.error_model import NoiseLayout
from brdf_infer.posterior._likelihood import ModelData
from brdf_infer.predict.observations import Observations

# how a padding row is filled, per field of Observations: the first row's value, or a constant
_ROW_FILL: dict[str, Any] = {
    "theta_i_deg": "first",
    "theta_s_deg": "first",
    "log_aperture": 0.0,
    "log_reflectance": 0.0,
    "sigma": 1.0,
    "cos_weight": "first",
    "phi_s_deg": "first",  # NaN (in the plane) or a finite azimuth: both valid
    "kernel": "first",  # every leaf (rows, nodes) or (rows,): the first row's nodes
}
# per field of NoiseLayout (every one per row): fill of padding rows, and whether it has a
# member axis (axis 1)
_NOISE_FILL: dict[str, tuple[float, bool]] = {
    "sigma_row": (1.0, False),
    "sample_members": (0.0, True),
    "sample_alone": (0.0, False),
    "calibration_members": (0.0, True),
    "calibration_alone": (0.0, False),
    "calibration_sd": (0.0, False),
    "rotation_members": (0.0, True),
    "rotation_alone": (0.0, False),
    "theta_s_per_rotation": (1.0, False),
    "rotation_deg": (0.0, False),
    "camera_deg": (0.0, False),
}
MEMBER_FIELDS = tuple(name for name, (_, members) in _NOISE_FILL.items() if members)


class PaddingError(ValueError):
    """Data sets that cannot be padded to one shape (a field this module does not know, or
    shapes that differ in more than rows and member columns)."""


def _check_fields() -> None:
    """Refuse clearly when a field was added to the data without a padding rule here."""
    unknown = set(Observations._fields) ^ set(_ROW_FILL)
    unknown |= set(NoiseLayout._fields) ^ set(_NOISE_FILL)
    unknown |= set(ModelData._fields) ^ {"rows", "noise", "mask"}
    if unknown:
        raise PaddingError(
            f"no padding rule for the data field(s) {sorted(unknown)} "
            "(brdf_infer/posterior/_padding.py)"
        )


def supports_padding() -> bool:
    """Whether :class:`ModelData` carries a row mask (padding rows are then exact no-ops)."""
    return "mask" in ModelData._fields


def paddable(model) -> bool:
    """Whether ``model`` may run on padded data: the data have a row mask, and no model site
    has a row or member axis (latent angles sample one variable per row and setting)."""
    errors = model.scene.errors
    if errors.angles_on and errors.angle_method == "latent":
        return False
    return supports_padding()


def row_count(data: ModelData) -> int:
    return int(np.shape(data.rows.theta_i_deg)[0])


def member_counts(data: ModelData) -> tuple[int, ...]:
    """(samples, calibration groups, rotation settings) with two or more rows: W's column
    blocks."""
    return tuple(int(np.shape(getattr(data.noise, name))[1]) for name in MEMBER_FIELDS)


def padded_signature(data: ModelData) -> dict[str, Any]:
    """What must agree for two data sets to be padded to one shape: the tree structure and
    every leaf's dtype and shape, the row axis and the member axes left out."""
    leaves, tree = jax.tree_util.tree_flatten_with_path(data)
    shapes = []
    for path, leaf in leaves:
        shape = list(np.shape(leaf))
        names = [getattr(key, "name", str(key)) for key in path]
        if names and names[-1] in MEMBER_FIELDS and names[0] == "noise":
            shape[1] = None
        shapes.append(([None, *shape[1:]] if shape else [], str(np.asarray(leaf).dtype)))
    return {"tree": str(tree), "shapes": shapes}


def _pad_rows(leaf, rows: int, fill) -> jnp.ndarray:
    """``leaf`` (rows₀, ...) grown to ``rows`` rows filled with ``fill`` ("first": row 0)."""
    leaf = jnp.asarray(leaf)
    extra = rows - leaf.shape[0]
    if extra == 0:
        return leaf
    if isinstance(fill, str):
        block = jnp.broadcast_to(leaf[:1], (extra, *leaf.shape[1:]))
    else:
        block = jnp.full((extra, *leaf.shape[1:]), fill, leaf.dtype)
    return jnp.concatenate([leaf, block.astype(leaf.dtype)])


def _pad_members(leaf, columns: int) -> jnp.ndarray:
    extra = columns - leaf.shape[1]
    if extra == 0:
        return leaf
    return jnp.concatenate([leaf, jnp.zeros((leaf.shape[0], extra), leaf.dtype)], axis=1)


def pad_data(data: ModelData, rows: int, members: tuple[int, ...]) -> ModelData:
    """``data`` padded to ``rows`` rows and ``members`` = (samples, calibration groups,
    rotation settings) member columns (module docstring); unchanged where it already has that
    shape.

    Raises:
        PaddingError: no mask in the data model, a field without a padding rule, or a target
            smaller than the data.
    """
    if not supports_padding():
        raise PaddingError("the posterior data carry no row mask: padding would not be exact")
    _check_fields()
    have_rows, have_members = row_count(data), member_counts(data)
    if rows < have_rows or any(m < h for m, h in zip(members, have_members, strict=True)):
        raise PaddingError(
            f"cannot pad {have_rows} rows and {have_members} member columns to {rows} and {members}"
        )
    if rows == have_rows and tuple(members) == have_members:
        return data
    observations = {}
    for name in Observations._fields:
        value = getattr(data.rows, name)
        fill = _ROW_FILL[name]
        observations[name] = (
            None
            if value is None
            else jax.tree_util.tree_map(lambda leaf, fill=fill: _pad_rows(leaf, rows, fill), value)
        )
    noise = {}
    width = dict(zip(MEMBER_FIELDS, members, strict=True))
    for name in NoiseLayout._fields:
        fill, has_members = _NOISE_FILL[name]
        value = _pad_rows(getattr(data.noise, name), rows, fill)
        noise[name] = _pad_members(value, width[name]) if has_members else value
    return ModelData(
        rows=Observations(**observations),
        noise=NoiseLayout(**noise),
        mask=_pad_rows(data.mask, rows, 0.0),
    )


def pad_datasets(datasets: list[ModelData]) -> list[ModelData]:
    """Every data set padded to the largest row count and the largest number of samples,
    calibration groups and rotation settings among them (module docstring); data sets that
    already have that shape are returned as they are.

    Raises:
        PaddingError: as :func:`pad_data`, or data sets whose shapes differ in more than rows
            and member columns (e.g. instrument kernels with different numbers of nodes).
    """
    if not datasets:
        return []
    signatures = [padded_signature(data) for data in datasets]
    if any(signature != signatures[0] for signature in signatures[1:]):
        raise PaddingError(
            "the data sets differ in more than their rows, samples, calibration groups and "
            "rotation settings (tree structure, kernel nodes or dtypes): they cannot share one "
            "shape"
        )
    rows = max(row_count(data) for data in datasets)
    members = tuple(int(m) for m in np.max([member_counts(d) for d in datasets], axis=0))
    return [pad_data(data, rows, members) for data in datasets]
