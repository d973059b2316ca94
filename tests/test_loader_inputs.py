"""Generated bad inputs for every loader (measurement CSV, scene TOML, Zemax .BSDF, parameter
JSON): each ends in a result that holds what the loader promises or in one BadInputError line
naming the file or option, never another exception, never a file written; the command line
prints that line (an option's field named as its flag) and exits 2
(``benchmarks._loader_inputs``).

The suite runs the profile of ``tests/conftest.py`` (60 inputs per loader; fixed under CI);
the ``slow`` set 5,000 per loader (the benchmark counts them too)."""

from __future__ import annotations

import io
import re
from contextlib import redirect_stderr, redirect_stdout

import pytest
from hypothesis import given, settings

from benchmarks._loader_inputs import LOADERS, run_loader
from brdf_infer.cli import main

SLOW_EXAMPLES = 5000


def _same_line_on_the_command_line(argv: list[str], message: str) -> None:
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        code = main(argv)
    assert (code, out.getvalue()) == (2, ""), (argv, err.getvalue())
    # an option's field (no file named before it) as the command line's flag: params → --params
    line = re.sub(r"^field '(\w+)'", lambda m: f"field '--{m[1].replace('_', '-')}'", message)
    assert err.getvalue() == f"brdf-infer: error: {line}\n"


def _property(name: str):
    loader = LOADERS[name]

    @given(loader.inputs())
    def every_input(generated) -> None:
        run_loader(loader, generated, _same_line_on_the_command_line)

    return every_input


@pytest.mark.full
@pytest.mark.parametrize("name", sorted(LOADERS))
def test_generated_inputs_end_in_a_result_or_one_line_and_exit_2(name):
    _property(name)()


@pytest.mark.slow  # ≈ 1 min per loader; the benchmark counts the same inputs
@pytest.mark.parametrize("name", sorted(LOADERS))
def test_five_thousand_generated_inputs_per_loader(name):
    settings(max_examples=SLOW_EXAMPLES)(_property(name))()
