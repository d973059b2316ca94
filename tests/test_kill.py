"""Kill at any moment, rerun, nothing wrong: ``run``, ``batch`` and ``export`` killed with
SIGKILL at random moments and run again end with the files of an uninterrupted run.

Each command first runs uninterrupted (its duration sets the range of the kill moments), then
into another folder it is started and killed ``KILLS`` times at uniformly random moments of
that duration (the same folder each time), and run once more to the end. The two folders must
hold the same files with the same contents: JSON without its timings and folder paths, every
netCDF group's arrays exactly, .BSDF tables without their time stamp; figures and HTML by name.
"""

from __future__ import annotations

import json
import os
import random
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from brdf_infer._internal import arviz as az
from brdf_infer._internal.outlock import LOCK_FILE
from tests.helpers import REPO, SUITE_WARMUP, fewer_rows, lya_scene_file, scaled_rows

pytestmark = pytest.mark.slow  # minutes: every kill restarts a process (run in the benchmark)

KILLS = int(os.environ.get("BRDF_INFER_KILLS", "4"))
SMALL = ["--chains", "2", "--draws", "150", "--warmup", str(SUITE_WARMUP)]
_STAMP = re.compile(r"export, \d{4}-\d\d-\d\dT[\d:]+\+00:00")


def _start(argv: list[str]) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "brdf_infer", *argv],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        cwd=REPO,
    )


def _finish(argv: list[str]) -> float:
    """Run ``brdf-infer ARGV`` to the end; its wall time [s]."""
    started = time.monotonic()
    process = _start(argv)
    _, err = process.communicate(timeout=900)
    assert process.returncode == 0, err[-3000:]
    return time.monotonic() - started


def _kill_and_rerun(
    argv: list[str], rerun: list[str], out: Path, whole: Path, seconds: float, seed: int
) -> None:
    """``argv`` (writing ``out``) killed ``KILLS`` times at random moments within ``seconds``,
    then ``rerun`` to the end. After every kill, ``out`` is either marked incomplete (its
    lock file) or empty or as complete as ``whole``, the uninterrupted run's folder."""
    rng = random.Random(seed)
    for attempt in range(KILLS):
        moment = rng.uniform(0.05, 1.0) * seconds
        process = _start(argv if attempt == 0 else rerun)
        try:
            process.wait(timeout=moment)
        except subprocess.TimeoutExpired:
            process.send_signal(signal.SIGKILL)
        process.communicate()
        if out.is_dir() and not (out / LOCK_FILE).exists() and any(out.iterdir()):
            _assert_same(out, whole)  # a folder without the lock file is complete
    _finish(rerun)


def _without_timings(value, out: Path):
    """JSON content without timings, with ``out`` written as ``<out>``."""
    if isinstance(value, dict):
        return {
            k: _without_timings(v, out)
            for k, v in value.items()
            if "seconds" not in k and k != "after_sampling"
        }
    if isinstance(value, list):
        return [_without_timings(v, out) for v in value]
    if isinstance(value, str):
        return value.replace(str(out.resolve()), "<out>").replace(str(out), "<out>")
    return value


def _contents(out: Path) -> dict[str, object]:
    """Every file under ``out`` (relative path) with the content the comparison uses."""
    contents: dict[str, object] = {}
    for path in sorted(out.rglob("*")):
        if path.is_dir():
            continue
        name = str(path.relative_to(out))
        if path.suffix == ".json":
            contents[name] = _without_timings(json.loads(path.read_text()), out)
        elif path.suffix == ".nc":
            idata = az.from_netcdf(path)
            contents[name] = {
                group: {k: np.asarray(v).tobytes() for k, v in idata[group].data_vars.items()}
                for group in idata.groups()
            }
        elif path.suffix == ".BSDF":
            contents[name] = _STAMP.sub("export", path.read_text())
        else:
            contents[name] = None  # figures, HTML: by name
    return contents


def _assert_same(ours: Path, theirs: Path) -> None:
    assert not (ours / LOCK_FILE).exists()
    mine, reference = _contents(ours), _contents(theirs)
    assert sorted(mine) == sorted(reference)
    for name in reference:
        assert mine[name] == reference[name], name


def test_run_killed_at_random_moments_and_rerun_ends_as_an_uninterrupted_run(tmp_path):
    argv = ["run", "lya", *SMALL]
    seconds = _finish([*argv, "--out", str(tmp_path / "whole")])
    again = [*argv, "--out", str(tmp_path / "killed")]
    _kill_and_rerun(again, again, tmp_path / "killed", tmp_path / "whole", seconds, seed=1)
    _assert_same(tmp_path / "killed", tmp_path / "whole")


def test_batch_killed_at_random_moments_and_resumed_ends_as_an_uninterrupted_batch(tmp_path):
    scenes = [
        lya_scene_file(tmp_path, "a"),
        lya_scene_file(tmp_path, "b", scaled_rows(tmp_path, 1.3)),
        lya_scene_file(tmp_path, "c", fewer_rows(tmp_path, "rows_c", 0.8)),
    ]
    argv = ["batch", *scenes, *SMALL]
    seconds = _finish([*argv, "--out", str(tmp_path / "whole")])
    again = [*argv, "--out", str(tmp_path / "killed")]
    killed, whole = tmp_path / "killed", tmp_path / "whole"
    _kill_and_rerun(again, [*again, "--resume"], killed, whole, seconds, seed=2)
    _assert_same(tmp_path / "killed", tmp_path / "whole")


def test_export_killed_at_random_moments_and_rerun_ends_as_an_uninterrupted_export(tmp_path):
    run = tmp_path / "run"
    _finish(["posterior", "lya", *SMALL, "--out", str(run)])
    argv = ["export", "--run", str(run), "--format", "zemax-bsdf", "--draws", "4"]
    seconds = _finish([*argv, "--out", str(tmp_path / "whole")])
    record = json.loads((run / "exports.json").read_text())
    again = [*argv, "--out", str(tmp_path / "killed")]
    _kill_and_rerun(again, again, tmp_path / "killed", tmp_path / "whole", seconds, seed=3)
    _assert_same(tmp_path / "killed", tmp_path / "whole")
    exports = json.loads((run / "exports.json").read_text())["exports"]  # the run's record
    assert [e["folder"] for e in exports] == [
        record["exports"][0]["folder"],
        str((tmp_path / "killed").resolve()),
    ]
