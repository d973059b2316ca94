"""The persistent compilation cache: used by default, off with --no-cache or
BRDF_INFER_CACHE=off."""

import json
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


@pytest.mark.full
def test_compiled_programs_are_kept_in_the_cache_folder(tmp_path):
    cache = tmp_path / "cache"
    result = run_tis(str(cache))
    assert result.returncode == 0, result.stderr
    assert any(cache.iterdir())


@pytest.mark.full
@pytest.mark.parametrize("how", ["--no-cache", "off"])
def test_the_cache_can_be_switched_off(tmp_path, how):
    cache = tmp_path / "cache"
    result = run_tis("off" if how == "off" else str(cache), *([how] if how != "off" else []))
    assert result.returncode == 0, result.stderr
    assert not cache.exists() or not any(cache.iterdir())


@pytest.mark.slow  # two cold processes
def test_a_half_written_cache_entry_is_never_served(tmp_path):
    """JAX writes an entry in place, without a lock, so a process may find one half-written
    (another is writing it, or was killed while writing it): it cannot decompress it, says
    so on stderr and compiles the program itself, with the same result."""
    cache = tmp_path / "cache"
    first = run_tis(str(cache))
    assert first.returncode == 0, first.stderr
    entries = [path for path in cache.iterdir() if path.is_file()]
    assert entries
    for path in entries:
        path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    again = run_tis(str(cache))
    assert again.returncode == 0, again.stderr
    assert "Error reading persistent compilation cache entry" in again.stderr
    ours, theirs = json.loads(again.stdout), json.loads(first.stdout)
    assert (ours["tis"], ours["abs_error"]) == (theirs["tis"], theirs["abs_error"])
