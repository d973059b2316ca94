"""What a design study shrinks: the ``--target`` of ``brdf-infer design`` (and of the scene's
``[studies] design``), parsed in plain Python (this module itself uses no JAX).

Targets (units are the paper's):

* ``tis:THETA`` — TIS(θi = THETA°) of Eq. (9) [fraction];
* ``pi_brdf0`` — π·BRDF0, the diffuse floor of Eq. (7) [-];
* ``PARAM`` — one parameter of Eq. (7) (``brdf0, a1, a2, a3, alpha, theta_s0``) in its unit;
* ``brdf:THETA_I,THETA_S`` — the in-plane BRDF at (θi, θs) [sr⁻¹] (θs signed, > 0 forward);
* ``all`` — every free parameter together, by the expected information gain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from brdf_infer.errors import BadInputError
from brdf_infer.model.params import PARAM_NAMES

DESIGN_BUDGET = 3  # rows chosen together by default (the scene's [design] and --budget)

TARGET_FORMS = "tis:THETA, pi_brdf0, a parameter (" + ", ".join(PARAM_NAMES) + ")"
TARGET_FORMS += ", brdf:THETA_I,THETA_S or all"


@dataclass(frozen=True)
class DesignTarget:
    """A parsed target.

    Attributes:
        kind: ``tis``, ``pi_brdf0``, ``param``, ``brdf`` or ``all``.
        angles_deg: (θi,) for ``tis``, (θi, θs) for ``brdf``, () otherwise [deg].
        parameter: the parameter's name for ``param``.
    """

    kind: str
    angles_deg: tuple[float, ...] = ()
    parameter: str = ""

    @property
    def name(self) -> str:
        """The JSON name: ``tis_70deg``, ``pi_brdf0``, ``alpha``, ``brdf_45_30deg``, ``all``."""
        if self.kind == "tis":
            return f"tis_{self.angles_deg[0]:g}deg"
        if self.kind == "brdf":
            return f"brdf_{self.angles_deg[0]:g}_{self.angles_deg[1]:g}deg"
        return self.parameter if self.kind == "param" else self.kind

    @property
    def label(self) -> str:
        """A human label with units."""
        if self.kind == "tis":
            return f"TIS({self.angles_deg[0]:g}°)"
        if self.kind == "brdf":
            return f"BRDF({self.angles_deg[0]:g}°, {self.angles_deg[1]:g}°) [sr⁻¹]"
        if self.kind == "pi_brdf0":
            return "π·BRDF0"
        return self.parameter if self.kind == "param" else "every free parameter (EIG)"


def _angle(text: str, low: float, high: float, field: str, file) -> float:
    try:
        value = float(text)
    except ValueError:
        raise BadInputError(f"expected an angle, got {text!r}", file=file, field=field) from None
    if not (math.isfinite(value) and low <= value <= high):
        raise BadInputError(f"angle {text} outside [{low:g}, {high:g}] deg", file=file, field=field)
    return value


def parse_target(text: str, *, field: str = "target", file=None) -> DesignTarget:
    """The target named by ``text`` (module docstring).

    Raises:
        BadInputError: an unknown target or an angle out of range, naming ``field``.
    """
    if not isinstance(text, str):
        raise BadInputError(f"expected a target string, got {text!r}", file=file, field=field)
    kind, _, rest = text.strip().partition(":")
    if kind == "tis" and rest:
        return DesignTarget("tis", (_angle(rest, 0.0, 89.0, field, file),))
    if kind == "brdf" and rest.count(",") == 1:
        theta_i, theta_s = rest.split(",")
        return DesignTarget(
            "brdf",
            (_angle(theta_i, 0.0, 89.0, field, file), _angle(theta_s, -89.0, 89.0, field, file)),
        )
    if not rest and kind in ("pi_brdf0", "all"):
        return DesignTarget(kind)
    if not rest and kind in PARAM_NAMES:
        return DesignTarget("param", parameter=kind)
    raise BadInputError(f"unknown target {text!r} (known: {TARGET_FORMS})", file=file, field=field)
