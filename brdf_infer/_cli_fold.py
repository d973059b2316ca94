"""``--fold`` / ``--no-fold``: the command-line override of the one fold switch (Eq. 10).

Products default to the physical BRDF (no folding, the conservative choice for a stray-light
budget); a posterior run's products follow its scene's ``[model] fold``. The article's Table 3
comparison folds explicitly with ``--fold``. ``--no-fold`` stays accepted (scripts use it).
"""

from __future__ import annotations

import argparse

from brdf_infer.errors import BadInputError


def add_fold_arguments(parser: argparse.ArgumentParser, default: str) -> None:
    """``--fold`` and ``--no-fold`` into ``args.fold`` (True, False; None when neither is
    given); ``default`` says in the help what neither means."""
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


def refuse_fold(requested: bool | None, family_name: str) -> None:
    """A family other than ``strumik2024`` has no Eq. (10) to fold with.

    Raises:
        BadInputError: ``--fold`` was asked for.
    """
    if requested:
        raise BadInputError(f"a run of {family_name} has no Eq. (10)", field="--fold")
