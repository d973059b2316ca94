"""The persistent compilation cache: used by default, off with --no-cache or
BRDF_INFER_CACHE=off."""

import os
import subprocess
import sys

import pytest

from tests.helpers import REPO


def run_tis(cache: str, *extra: str) -> subprocess.CompletedProcess:
    environment = {**os.environ, "BRDF_INFER_CACHE": cache}
    return subprocess.run(
        [sys.executable, "-m", "brdf_infer", "tis", "--theta-i", "70", "--json", *extra],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=environment,
        timeout=300,
    )


def test_compiled_programs_are_kept_in_the_cache_folder(tmp_path):
    cache = tmp_path / "cache"
    result = run_tis(str(cache))
    assert result.returncode == 0, result.stderr
    assert any(cache.iterdir())


@pytest.mark.parametrize("how", ["--no-cache", "off"])
def test_the_cache_can_be_switched_off(tmp_path, how):
    cache = tmp_path / "cache"
    result = run_tis("off" if how == "off" else str(cache), *([how] if how != "off" else []))
    assert result.returncode == 0, result.stderr
    assert not cache.exists() or not any(cache.iterdir())
