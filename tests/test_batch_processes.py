"""``brdf-infer batch --num-processes N``: the scenes divided among processes that
``jax.distributed`` connects, each run folder written once by its owner, the draws of a batch
in one process, and a failing process that stops the others with one line."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from brdf_infer._internal import arviz as az
from brdf_infer._internal.processes import Processes, resolve_processes
from brdf_infer.errors import BadInputError
from tests.helpers import fewer_rows, lya_scene_file, run_cli, scaled_rows

TINY = ["--chains", "2", "--draws", "20", "--warmup", "20"]
PEER_TIMEOUT = 5.0  # [s] in these tests (default 60)
WATCHDOG = 600  # [s] no process of a test may run longer


# ---------------------------------------------------------------------------------- pure logic


def test_scene_k_goes_to_process_k_mod_n():
    three = [Processes(3, index) for index in range(3)]
    owners = [[p.owns(k) for p in three].index(True) for k in range(8)]
    assert owners == [0, 1, 2, 0, 1, 2, 0, 1]
    assert all(sum(p.owns(k) for p in three) == 1 for k in range(8))  # exactly one owner
    assert Processes().owns(5) and not Processes().several


def test_process_options_and_their_environment():
    assert resolve_processes(None, 1, None, environ={}) == Processes()
    both = resolve_processes("127.0.0.1:1234", 2, 1, environ={})
    assert both == Processes(2, 1, "127.0.0.1:1234")
    slurm = {"SLURM_PROCID": "3", "SLURM_JOB_ID": "77"}
    assert resolve_processes(None, 4, None, environ=slurm) == Processes(4, 3, None)
    env = {"SLURM_PROCID": "0", "JAX_COORDINATOR_ADDRESS": "node1:5000"}
    assert resolve_processes(None, 2, None, environ=env).coordinator == "node1:5000"
    cases = [
        (("h:1", 0, None), "num_processes", "must be at least 1, got 0"),
        (("h:1", 2, 2), "process_id", "2 is out of range for 2 process(es) (0 to 1)"),
        (("h:1", 2, -1), "process_id", "-1 is out of range"),
        (("h:1", 1, 1), "process_id", "1 is out of range for 1 process(es)"),
        (("h:1", 2, None), "process_id", "is needed with --num-processes 2"),
        ((None, 2, 0), "coordinator", "HOST:PORT of process 0 is needed"),
        (("nohost", 2, 0), "coordinator", "'nohost' is not HOST:PORT"),
        (("h:99999", 2, 0), "coordinator", "is not HOST:PORT"),
    ]
    for arguments, field, words in cases:
        with pytest.raises(BadInputError) as caught:
            resolve_processes(*arguments, environ={})
        assert caught.value.field == field and words in str(caught.value), arguments
    with pytest.raises(BadInputError, match="must be above 0 s"):
        resolve_processes(None, 1, None, 0.0, environ={})


@pytest.mark.parametrize(
    ("options", "line"),
    [
        (
            ["--num-processes", "2", "--process-id", "2", "--coordinator", "127.0.0.1:9"],
            "field '--process-id': 2 is out of range for 2 process(es) (0 to 1)",
        ),
        (
            ["--num-processes", "2", "--process-id", "0", "--coordinator", "localhost"],
            "field '--coordinator': 'localhost' is not HOST:PORT (a port from 1 to 65535)",
        ),
        (["--num-processes", "0"], "field '--num-processes': must be at least 1, got 0"),
    ],
)
def test_bad_process_options_are_one_line_and_create_nothing(tmp_path, capsys, options, line):
    out = tmp_path / "out"
    code, text, err = run_cli("batch", "lya", *options, "--out", str(out), capsys=capsys)
    assert code == 2 and text == "" and "Traceback" not in err
    assert err.strip() == f"brdf-infer: error: {line}"
    assert not out.exists()


# ---------------------------------------------------------------------------------- processes


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _scenes(folder: Path) -> list[str]:
    """a (the bundled rows), b (× 1.3), c (23 rows × 0.8: padded to a's shape): process 0 owns
    a and c, process 1 owns b."""
    return [
        lya_scene_file(folder, "a"),
        lya_scene_file(folder, "b", scaled_rows(folder, 1.3)),
        lya_scene_file(folder, "c", fewer_rows(folder, "rows_c", 0.8)),
    ]


def _start_pair(folder: Path, out: Path, *extra: str) -> list[tuple[subprocess.Popen, Path]]:
    """Processes 0 and 1 of a batch of ``_scenes`` into ``out``; (process, its stderr file)
    each, stdout in ``stdout-<i>.txt``."""
    port = _free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("SLURM_", "JAX_COORD"))}
    started = []
    for index in range(2):
        command = [
            *(sys.executable, "-m", "brdf_infer", "batch", *_scenes(folder), *TINY),
            *("--out", str(out), "--num-processes", "2", "--process-id", str(index)),
            *("--coordinator", f"127.0.0.1:{port}", "--peer-timeout", str(PEER_TIMEOUT)),
            *extra,
        ]
        stderr = folder / f"stderr-{index}.txt"
        with stderr.open("w") as err, (folder / f"stdout-{index}.txt").open("w") as text:
            started.append((subprocess.Popen(command, stdout=text, stderr=err, env=env), stderr))
    return started


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
    """batch.json without timings, devices, process count and folder paths."""
    scenes = [{**e, "out": e["out"] and Path(e["out"]).name} for e in payload["scenes"]]
    drop = ("seconds", "compile_seconds", "devices", "processes")
    return {k: v for k, v in payload.items() if k not in drop} | {"scenes": scenes}


@pytest.fixture(scope="module")
def pair_run(tmp_path_factory):
    """The same three scenes in one process, then over two (times in seconds)."""
    folder = tmp_path_factory.mktemp("processes")
    clock = time.monotonic()
    single = folder / "single"
    from brdf_infer.cli import main

    assert main(["batch", *_scenes(folder), *TINY, "--out", str(single)]) == 0
    seconds = {"single": time.monotonic() - clock}
    clock = time.monotonic()
    out = folder / "pair"
    started = _start_pair(folder, out)
    codes = _wait(started)
    seconds["pair"] = time.monotonic() - clock
    errors = [stderr.read_text() for _, stderr in started]
    assert codes == [0, 0], errors
    print(f"\n3 tiny scenes: one process {seconds['single']:.1f} s, two {seconds['pair']:.1f} s")
    return folder, single, out, errors


@pytest.mark.slow  # compiles the group's program in three processes
def test_two_processes_write_each_scene_once_with_the_draws_of_one(pair_run):
    folder, single, out, errors = pair_run
    assert sorted(p.name for p in out.iterdir()) == ["a", "b", "batch.json", "c"]  # nothing left
    written = [
        {line.split(":")[0].strip() for line in e.splitlines() if ": " + str(out) in line}
        for e in errors
    ]
    assert written == [{"a", "c"}, {"b"}]  # each folder by its owner, once
    assert "2 of them here (process 0)" in errors[0] and "1 of them here (process 1)" in errors[1]
    assert "Traceback" not in errors[0] + errors[1]
    assert (folder / "stdout-1.txt").read_text() == ""  # one table: process 0's
    assert "3 scene(s) in 1 compiled group(s)" in (folder / "stdout-0.txt").read_text()
    ours, theirs = (json.loads((d / "batch.json").read_text()) for d in (out, single))
    assert ours["processes"] == 2 and theirs["processes"] == 1
    assert _comparable(ours) == _comparable(theirs)
    for name in ("a", "b", "c"):  # threads mode, the same keys and padded shape: bit for bit
        mine = az.from_netcdf(out / name / "posterior.nc").posterior
        one = az.from_netcdf(single / name / "posterior.nc").posterior
        assert set(mine.data_vars) == set(one.data_vars)
        for site in one.data_vars:
            np.testing.assert_array_equal(np.asarray(mine[site]), np.asarray(one[site]))


@pytest.mark.slow  # starts two processes that compile
def test_a_killed_process_stops_the_other_with_one_line(tmp_path):
    """Process 1 killed (SIGKILL) while it compiles or samples: process 0 hears no heartbeat
    for --peer-timeout s and stops within seconds, exit 1, naming process 1; the complete
    folders stay, nothing half-written, batch.json marks the batch interrupted."""
    out = tmp_path / "out"
    started = _start_pair(tmp_path, out)
    second, stderr = started[1]
    deadline = time.monotonic() + WATCHDOG
    while "group 1/1" not in stderr.read_text():
        assert second.poll() is None and time.monotonic() < deadline, stderr.read_text()
        time.sleep(0.1)
    time.sleep(2.0)
    second.send_signal(signal.SIGKILL)
    killed = time.monotonic()
    codes = _wait(started)
    seconds = time.monotonic() - killed
    error = started[0][1].read_text()
    assert codes == [1, -signal.SIGKILL], error
    assert seconds < 3 * PEER_TIMEOUT + 10, seconds  # peer timeout + a heartbeat + the grace
    assert "Traceback" not in error
    assert error.strip().splitlines()[-1] == (
        f"brdf-infer: error: process 1 of 2 stopped responding (no heartbeat for "
        f"{PEER_TIMEOUT:g} s: killed?) (process 0 stopped; {out / 'batch.json'} lists the "
        "complete scenes)"
    )
    payload = json.loads((out / "batch.json").read_text())
    assert payload["interrupted"] is True
    done = {e["scene"] for e in payload["scenes"] if e["error"] is None}
    hidden = [p.name for p in out.iterdir() if p.name.startswith(".")]
    assert not any(".partial-" in name or ".batch-" in name for name in hidden), hidden
    assert {p.name for p in out.iterdir() if p.is_dir() and p.name[0] != "."} == done
    assert "b" not in done
    print(f"\nprocess 0 stopped {seconds:.1f} s after process 1 was killed")


@pytest.mark.slow  # starts two processes; process 1 compiles until it is stopped
def test_a_failing_coordinator_stops_the_other_with_one_line(pair_run, tmp_path):
    """Process 0 finds a run of another batch in a folder it owns (--resume with another
    seed): it ends with its own error (exit 2), and process 1 with one line naming it
    (exit 1), within seconds."""
    import shutil

    _, _, out, _ = pair_run
    resumed = tmp_path / "out"
    shutil.copytree(out, resumed)
    shutil.rmtree(resumed / "b")  # process 1 has work to do
    clock = time.monotonic()
    started = _start_pair(tmp_path, resumed, "--resume", "--seed", "1")
    codes = _wait(started)
    seconds = time.monotonic() - clock
    errors = [stderr.read_text() for _, stderr in started]
    assert codes == [2, 1], errors
    assert "Traceback" not in errors[0] + errors[1]
    own = (
        f"{resumed / 'a'}, field '--resume': holds a complete run of another batch (differs "
        "in: --seed); run the batch without --resume to replace it, or into another --out"
    )
    assert errors[0].strip().splitlines()[-1] == f"brdf-infer: error: {own}"
    assert errors[1].strip().splitlines()[-1] == (
        f"brdf-infer: error: process 0 of 2 failed: {own} (process 1 stopped)"
    )
    assert not (resumed / "b").exists()
    assert not [p for p in resumed.iterdir() if ".batch-" in p.name or ".partial-" in p.name]
    print(f"\nboth processes ended {seconds:.1f} s after they started")


@pytest.mark.slow  # starts two processes (no compile: process 0 stops before any work)
def test_a_coordinator_that_cannot_hold_the_folder_stops_both(tmp_path):
    """Another writer holds --out: process 0 says so (exit 2), process 1 that process 0 could
    not start the batch (exit 1); nothing is written."""
    from brdf_infer._internal.outlock import writing

    out = tmp_path / "out"
    with writing(out, "test"):
        clock = time.monotonic()
        started = _start_pair(tmp_path, out)
        codes = _wait(started, timeout=120)
        seconds = time.monotonic() - clock
    errors = [stderr.read_text() for _, stderr in started]
    assert codes == [2, 1], errors
    assert "Traceback" not in errors[0] + errors[1]
    assert "is being written by 'brdf-infer test'" in errors[0].strip().splitlines()[-1]
    assert errors[1].strip().splitlines()[-1] == (
        "brdf-infer: error: process 0 of 2 could not start the batch (process 1 stopped)"
    )
    assert list(out.iterdir()) == []
    print(f"\nboth processes ended {seconds:.1f} s after they started")
