"""A write that fails (a full disk, a file-size limit, a read-only folder) leaves no partial
file, keeps what was there, and says which file could not be written (one line, exit 2).

A full disk is simulated by a file-size limit (``RLIMIT_FSIZE``: a write past it fails with
EFBIG as one past a full disk fails with ENOSPC, through the same code), which works for any
user; read-only folders only where the tests do not run as root (root writes anyway)."""

from __future__ import annotations

import contextlib
import os
import resource
import signal
from pathlib import Path

import numpy as np
import pytest

from brdf_infer._internal import arviz as az
from brdf_infer._internal.atomic import atomic_write_bytes
from brdf_infer.posterior._results import write_inference_data
from tests.helpers import run_cli


@contextlib.contextmanager
def file_size_limit(size: int):
    """Writes past ``size`` bytes fail with EFBIG in this process while the block runs."""
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # EFBIG instead of the signal
    resource.setrlimit(resource.RLIMIT_FSIZE, (size, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, handler)


def test_a_failed_write_keeps_the_old_file_and_names_the_new_one(tmp_path):
    target, results = tmp_path / "bands.json", tmp_path / "posterior.nc"
    target.write_bytes(b"old")
    results.write_bytes(b"old run")
    idata = az.from_dict(posterior={"brdf0": np.zeros((2, 20_000))})
    with file_size_limit(10_000):
        with pytest.raises(OSError) as info:
            atomic_write_bytes(target, b"x" * 100_000)
        assert info.value.filename == str(target)
        assert info.value.strerror == "cannot write: File too large"
        with pytest.raises(OSError) as info:
            write_inference_data(idata, results)
        assert info.value.filename == str(results)
    assert target.read_bytes() == b"old" and results.read_bytes() == b"old run"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bands.json", "posterior.nc"]


def test_a_command_whose_write_fails_says_which_file_and_leaves_nothing(tmp_path, capsys):
    argv = ["export", "--params", "uv-paper", "--theta-i", "70", "--azimuth-step", "45"]
    argv += ["--radial-step", "10"]
    code, _, err = run_cli(*argv, "--out", str(tmp_path / "first"), capsys=capsys)  # compiles
    assert code == 0, err
    assert (tmp_path / "first" / "params.bsdf").stat().st_size > 1000
    out = tmp_path / "out"
    with file_size_limit(1000):
        code, text, err = run_cli(*argv, "--out", str(out), capsys=capsys)
    assert (code, text) == (2, "")
    assert err == f"brdf-infer: error: {out / 'params.bsdf'}: cannot write: File too large\n"
    assert not out.exists()  # nothing was written: not even the folder (or its lock) stays


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_a_read_only_folder_is_refused_before_any_work(tmp_path, capsys):
    folder = tmp_path / "ro"
    (folder / "run").mkdir(parents=True)
    folder.chmod(0o500)
    (folder / "run").chmod(0o500)
    try:
        for out in (folder / "new", folder / "run"):
            code, text, err = run_cli("run", "--out", str(out), capsys=capsys)
            assert (code, text) == (2, "") and err.count("\n") == 1, err
            assert f"{out}, field '--out': cannot write here" in err
        assert sorted(Path(p).name for p in folder.iterdir()) == ["run"]
    finally:
        (folder / "run").chmod(0o700)
        folder.chmod(0o700)


def test_a_written_file_has_the_mode_of_a_plain_open_and_the_umask_is_never_set(
    tmp_path, monkeypatch
):
    """The umask is process-wide: setting it (the only way to read it) races with every other
    thread creating a file. An atomic write creates its temporary file with mode 0o666, which
    the umask narrows as for any new file."""
    plain = tmp_path / "plain.json"
    plain.write_text("{}")

    def refuse(mask):
        raise AssertionError("os.umask called")

    monkeypatch.setattr(os, "umask", refuse)
    written = atomic_write_bytes(tmp_path / "written.json", b"{}")
    assert (written.stat().st_mode & 0o777) == (plain.stat().st_mode & 0o777)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plain.json", "written.json"]
