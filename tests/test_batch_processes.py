"""``brdf-infer batch --shard K/N``: the scenes divided among independent processes, each run
folder written once by its shard, the draws of a batch in one process, ``batch.json`` written
by the last shard to finish; a killed shard leaves the output folder incomplete until a rerun
finishes it."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from brdf_infer._internal import arviz as az
from brdf_infer._internal.outlock import require_complete, shard_lock_file
from brdf_infer._internal.shards import Shard, resolve_shard
from brdf_infer.errors import BadInputError
from tests.helpers import fewer_rows, lya_scene_file, run_cli, scaled_rows

TINY = ["--chains", "2", "--draws", "20", "--warmup", "20"]
WATCHDOG = 600  # [s] no process of a test may run longer


# ---------------------------------------------------------------------------------- pure logic


def test_scene_k_goes_to_shard_k_mod_n():
    three = [Shard(index, 3) for index in range(3)]
    owners = [[s.owns(k) for s in three].index(True) for k in range(8)]
    assert owners == [0, 1, 2, 0, 1, 2, 0, 1]
    assert all(sum(s.owns(k) for s in three) == 1 for k in range(8))  # exactly one owner
    assert Shard().owns(5) and str(Shard(1, 3)) == "1/3"


def test_shard_options_and_slurm():
    assert resolve_shard(None, environ={"SLURM_PROCID": "1", "SLURM_NTASKS": "2"}) == Shard()
    assert resolve_shard("1/4", environ={}) == Shard(1, 4)
    slurm = {"SLURM_PROCID": "3", "SLURM_NTASKS": "4"}
    assert resolve_shard("slurm", environ=slurm) == Shard(3, 4)
    cases = [
        ("2/2", {}, "2/2 is not K/N with 0 <= K < N"),
        ("-1/2", {}, "-1/2 is not K/N"),
        ("1", {}, "1/ is not K/N"),
        ("slurm", {"SLURM_PROCID": "0"}, "slurm needs SLURM_PROCID and SLURM_NTASKS"),
        ("slurm", {"SLURM_PROCID": "4", "SLURM_NTASKS": "4"}, "4/4 is not K/N"),
    ]
    for text, environ, words in cases:
        with pytest.raises(BadInputError) as caught:
            resolve_shard(text, environ=environ)
        assert caught.value.field == "shard" and words in str(caught.value), text


def test_a_bad_shard_is_one_line_and_creates_nothing(tmp_path, capsys):
    out = tmp_path / "out"
    code, text, err = run_cli("batch", "lya", "--shard", "2/2", "--out", str(out), capsys=capsys)
    assert code == 2 and text == "" and "Traceback" not in err
    assert err.strip() == "brdf-infer: error: field '--shard': 2/2 is not K/N with 0 <= K < N"
    assert not out.exists()


# ---------------------------------------------------------------------------------- processes


def _scenes(folder: Path) -> list[str]:
    """a (the bundled rows), b (× 1.3), c (23 rows × 0.8: padded to a's shape): shard 0/2 runs
    a and c, shard 1/2 runs b."""
    return [
        lya_scene_file(folder, "a"),
        lya_scene_file(folder, "b", scaled_rows(folder, 1.3)),
        lya_scene_file(folder, "c", fewer_rows(folder, "rows_c", 0.8)),
    ]


def _start(folder: Path, out: Path, name: str, *extra: str) -> tuple[subprocess.Popen, Path]:
    """``brdf-infer batch`` of ``_scenes`` into ``out``; the process and its stderr file (its
    stdout in ``stdout-<name>.txt``)."""
    command = [sys.executable, "-m", "brdf_infer", "batch", *_scenes(folder), *TINY]
    stderr = folder / f"stderr-{name}.txt"
    with stderr.open("w") as err, (folder / f"stdout-{name}.txt").open("w") as text:
        process = subprocess.Popen([*command, "--out", str(out), *extra], stdout=text, stderr=err)
    return process, stderr


def _wait(started, timeout: float = WATCHDOG) -> list[int]:
    """Every process's exit code; the watchdog kills them all after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    codes = []
    for process, _ in started:
        try:
            codes.append(process.wait(timeout=max(1.0, deadline - time.monotonic())))
        except subprocess.TimeoutExpired:
            for other, _ in started:
                other.kill()
            pytest.fail(f"hung: still running after {timeout:.0f} s")
    return codes


def _comparable(payload: dict) -> dict:
    """batch.json without timings, devices, shard count and folder paths."""
    scenes = [{**e, "out": e["out"] and Path(e["out"]).name} for e in payload["scenes"]]
    drop = ("seconds", "compile_seconds", "devices", "shards")
    return {k: v for k, v in payload.items() if k not in drop} | {"scenes": scenes}


def _assert_same_draws(out: Path, single: Path) -> None:
    for name in ("a", "b", "c"):  # threads mode, the same keys and padded shape: bit for bit
        mine = az.from_netcdf(out / name / "posterior.nc").posterior
        one = az.from_netcdf(single / name / "posterior.nc").posterior
        assert set(mine.data_vars) == set(one.data_vars)
        for site in one.data_vars:
            np.testing.assert_array_equal(np.asarray(mine[site]), np.asarray(one[site]))


@pytest.fixture(scope="module")
def single_run(tmp_path_factory):
    """The three scenes in one process."""
    folder = tmp_path_factory.mktemp("shards")
    single = folder / "single"
    from brdf_infer.cli import main

    assert main(["batch", *_scenes(folder), *TINY, "--out", str(single)]) == 0
    return folder, single


@pytest.mark.slow  # compiles the group's program in three processes
def test_two_shards_write_each_scene_once_with_the_draws_of_one_process(single_run):
    folder, single = single_run
    out = folder / "pair"
    clock = time.monotonic()
    started = [_start(folder, out, str(k), "--shard", f"{k}/2") for k in range(2)]
    codes = _wait(started)
    seconds = time.monotonic() - clock
    errors = [stderr.read_text() for _, stderr in started]
    assert codes == [0, 0], errors
    assert sorted(p.name for p in out.iterdir()) == ["a", "b", "batch.json", "c"]  # nothing left
    written = [
        {line.split(":")[0].strip() for line in e.splitlines() if ": " + str(out) in line}
        for e in errors
    ]
    assert written == [{"a", "c"}, {"b"}]  # each folder by its shard, once
    assert "2 of them in shard 0/2" in errors[0] and "1 of them in shard 1/2" in errors[1]
    assert "Traceback" not in errors[0] + errors[1]
    outputs = [(folder / f"stdout-{k}.txt").read_text() for k in range(2)]
    merged = [o.endswith(f"summary in {out / 'batch.json'}\n") for o in outputs]
    assert sorted(merged) == [False, True], outputs  # the last to finish wrote batch.json
    waited = outputs[merged.index(False)]
    assert waited.endswith("batch.json: written by the last shard to finish\n"), waited
    ours, theirs = (json.loads((d / "batch.json").read_text()) for d in (out, single))
    assert ours["shards"] == 2 and theirs["shards"] == 1
    assert _comparable(ours) == _comparable(theirs)
    _assert_same_draws(out, single)
    print(f"\n3 tiny scenes in two shards side by side: {seconds:.1f} s")


@pytest.mark.slow  # starts a shard that compiles, then a batch that finishes it
def test_a_killed_shard_leaves_the_folder_incomplete_until_a_rerun_finishes_it(single_run, capsys):
    """Shard 1/2 killed (SIGKILL) while it compiles or samples: its marker stays, every reader
    refuses the output folder, no batch.json; a second shard 1/2 at once is refused; the
    batch with --resume (no shard) runs what is missing, writes batch.json equal to the one
    process's, and leaves the folder complete."""
    folder, single = single_run
    out = folder / "killed"
    process, stderr = _start(folder, out, "killed", "--shard", "1/2")
    deadline = time.monotonic() + WATCHDOG
    while "group 1/1" not in stderr.read_text():
        assert process.poll() is None and time.monotonic() < deadline, stderr.read_text()
        time.sleep(0.1)
    code, _, err = run_cli(
        "batch", *_scenes(folder), *TINY, "--out", str(out), "--shard", "1/2", capsys=capsys
    )
    assert code == 2 and "is being written by 'brdf-infer batch --shard 1/2' (process" in err
    process.send_signal(signal.SIGKILL)
    process.wait()
    assert (out / shard_lock_file(1, 2)).exists() and not (out / "batch.json").exists()
    with pytest.raises(BadInputError, match=r"incomplete: 'brdf-infer batch --shard 1/2'"):
        require_complete(out)
    code, text, err = run_cli(
        "batch", *_scenes(folder), *TINY, "--out", str(out), "--resume", capsys=capsys
    )
    assert code == 0, err
    assert "resume: 0 scene(s) complete" in err and "Traceback" not in err
    assert f"summary in {out / 'batch.json'}" in text
    require_complete(out)
    assert sorted(p.name for p in out.iterdir() if p.name != "batch.json") == ["a", "b", "c"]
    ours, theirs = (json.loads((d / "batch.json").read_text()) for d in (out, single))
    assert _comparable(ours) == _comparable(theirs)
    _assert_same_draws(out, single)
