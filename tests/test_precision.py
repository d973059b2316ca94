"""float64: importing the package changes no JAX setting; the command line switches float64
(and the compilation cache) on; the library's entry points refuse float32 in one line and
switch nothing."""

import os
import subprocess
import sys
import textwrap

import jax
import pytest

from brdf_infer._internal.precision import Float32Error, require_float64
from tests.helpers import REPO, run_cli


def _python(code: str, **environment: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        cwd=REPO,
        env={**os.environ, **environment},
        timeout=300,
    )


@pytest.mark.full
def test_importing_the_package_changes_no_jax_setting(tmp_path):
    result = _python(
        """
        import jax
        import brdf_infer, brdf_infer.cli, brdf_infer.posterior, brdf_infer.workflow
        import brdf_infer.report, brdf_infer.workflow.batch, brdf_infer.design, brdf_infer.fit.lsq
        print(jax.config.jax_enable_x64, jax.config.jax_compilation_cache_dir)
        brdf_infer.use_float64()
        brdf_infer.use_float64()  # again: nothing more
        import jax.numpy as jnp
        print(jnp.asarray(1.0).dtype, jax.config.jax_compilation_cache_dir)
        """,
        BRDF_INFER_CACHE=str(tmp_path / "cache"),
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == ["False None", f"float64 {tmp_path / 'cache'}"]


@pytest.mark.full
def test_an_entry_point_refuses_float32_in_one_line_and_switches_nothing():
    """``load_scene`` in float32 (no JAX array yet, or one made) refuses in one line naming
    ``brdf_infer.use_float64()`` and leaves ``jax_enable_x64`` and the cache as they were;
    after ``brdf_infer.use_float64()`` it loads."""
    result = _python(
        """
        import jax
        import jax.numpy as jnp
        import brdf_infer
        from brdf_infer import Float32Error
        from brdf_infer.scene import load_scene
        for made in (False, True):
            kept = jnp.ones(3) if made else None  # a float32 array
            try:
                load_scene("lya")
            except Float32Error as error:
                print(error)
            print(jax.config.jax_enable_x64, jax.config.jax_compilation_cache_dir)
        brdf_infer.use_float64()
        print(load_scene("lya").name)
        """,
        BRDF_INFER_CACHE="off",
    )
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert len(lines) == 5, lines
    for refusal, state in (lines[0:2], lines[2:4]):
        assert "float32" in refusal and "brdf_infer.use_float64()" in refusal
        assert state == "False None"
    assert lines[4] == "lya"


@pytest.mark.full
def test_the_command_line_switches_float64_on(capsys):
    jax.config.update("jax_enable_x64", False)
    try:
        with pytest.raises(Float32Error, match=r"brdf_infer\.use_float64\(\)"):
            require_float64()
        code, _, err = run_cli("tis", capsys=capsys)
        assert code == 0, err
        require_float64()
    finally:
        jax.config.update("jax_enable_x64", True)


def test_the_report_reads_its_rows_in_float64_or_refuses(nuts_run):
    """``write_report`` reads the scene's rows again: in float32 a table's rows at the horizon
    select differently (1984 of 1986 on a 2 × 10³-row table, then an IndexError); it refuses."""
    result = _python(
        f"""
        import jax.numpy as jnp
        from pathlib import Path
        from brdf_infer import Float32Error
        from brdf_infer.report import write_report
        kept = jnp.ones(3)  # float32
        try:
            write_report(Path({str(nuts_run.out)!r}))
        except Float32Error as error:
            print("refused:", error)
        """
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("refused:") and "use_float64()" in result.stdout
