"""One writer per output folder; a folder a writer left incomplete is refused by every reader
and taken over by the next producer."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from brdf_infer._internal.atomic import atomic_write_json
from brdf_infer._internal.outlock import ADDING_LOCK_FILE, LOCK_FILE, require_complete, writing
from brdf_infer.errors import BadInputError
from tests.helpers import run_cli

# A writer in another process: holds the folder, writes a file and leaves the temporary file
# of an atomic write it never finished, then waits to be killed.
_HOLDER = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    from brdf_infer._internal.atomic import atomic_write_json
    from brdf_infer._internal.outlock import writing

    folder = Path(sys.argv[1])
    with writing(folder, "run"):
        atomic_write_json(folder / "fit_lsq.json", {"cost": 1.0})
        (folder / ".summary.json.abcd1234.tmp").write_text("{half")
        print("held", flush=True)
        time.sleep(120)
    """
)


def _one_error_line(code: int, out: str, err: str) -> str:
    assert code == 2 and out == "", (code, out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_one_writer_per_folder_and_a_dead_writers_folder_is_incomplete(tmp_path, capsys):
    """While another process writes the folder a second writer (run) is refused at once and a
    reader (tis --run) is told it is being written; once that process is killed, every reader
    refuses the incomplete folder in one line, a command that only adds to it (report) does
    not take it over, and the next producer does: the dead writer's temporary files go, and
    the folder is complete when the producer finishes. An adder that dies leaves the folder
    complete."""
    folder = tmp_path / "out"
    holder = subprocess.Popen(
        [sys.executable, "-c", _HOLDER, str(folder)], stdout=subprocess.PIPE, text=True
    )
    try:
        assert holder.stdout.readline().strip() == "held"
        started = time.perf_counter()
        line = _one_error_line(*run_cli("run", "--out", str(folder), capsys=capsys))
        assert time.perf_counter() - started < 10.0  # before any compilation
        assert f"{folder}, field '--out': is being written by 'brdf-infer run' (process " in line
        assert f"process {holder.pid} on " in line and "one writer per folder" in line
        line = _one_error_line(*run_cli("tis", "--run", str(folder), capsys=capsys))
        assert "is being written by 'brdf-infer run'" in line and "wait until it finishes" in line
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
    owner = json.loads((folder / LOCK_FILE).read_text())
    assert owner["pid"] == holder.pid and owner["command"] == "run"
    for argv in (
        ["tis", "--run", str(folder)],
        ["report", str(folder)],
        ["export", "--run", str(folder), "--out", str(tmp_path / "bsdf")],
        ["raytrace", "--run", str(folder)],
        ["design", str(folder), "--out", str(tmp_path / "design")],
    ):
        line = _one_error_line(*run_cli(*argv, capsys=capsys))
        assert line.startswith(f"brdf-infer: error: {folder}: incomplete: 'brdf-infer run' ")
        assert "stopped before finishing it; run that command again" in line
    assert not (tmp_path / "bsdf").exists() and not (tmp_path / "design").exists()
    adding = writing(folder, "report", adds=True)  # report only adds to a complete folder
    with pytest.raises(BadInputError, match="incomplete"), adding:
        pass
    with writing(folder, "run") as claim:
        assert claim.previous.pid == holder.pid and claim.previous.command == "run"
        assert not (folder / ".summary.json.abcd1234.tmp").exists()  # the dead writer's
        assert (folder / "fit_lsq.json").exists()
        atomic_write_json(folder / "summary.json", {})
    require_complete(folder)
    assert not (folder / LOCK_FILE).exists()
    # an adder killed while adding (its lock file left) leaves the folder complete
    (folder / ADDING_LOCK_FILE).write_text(json.dumps({"pid": holder.pid, "command": "report"}))
    require_complete(folder)
    with writing(folder, "report", adds=True) as claim:
        assert claim.previous.pid == holder.pid
    assert not (folder / ADDING_LOCK_FILE).exists()


def test_bad_input_leaves_no_folder_and_an_error_after_writing_leaves_it_incomplete(tmp_path):
    fresh = tmp_path / "a" / "b"
    with pytest.raises(BadInputError), writing(fresh, "run"):
        assert (fresh / LOCK_FILE).is_file()
        raise BadInputError("bad scene")
    assert not (tmp_path / "a").exists()
    folder = tmp_path / "run"
    with pytest.raises(RuntimeError), writing(folder, "posterior"):
        atomic_write_json(folder / "bands.json", {})
        raise RuntimeError("sampler failed")
    with pytest.raises(BadInputError, match=r"stopped before finishing it \(RuntimeError\)"):
        require_complete(folder)
    # takes it over, writes nothing: still incomplete
    with pytest.raises(BadInputError), writing(folder, "posterior"):
        raise BadInputError("bad option")
    assert json.loads((folder / LOCK_FILE).read_text())["stopped"] == "RuntimeError"
    with writing(folder, "posterior"), writing(folder, "report"):  # re-entrant in a process
        atomic_write_json(folder / "bands.json", {})
    require_complete(folder)


def test_claims_are_re_entrant_within_a_process(tmp_path):
    """Claims are per process: ``run`` holds its folder and calls ``posterior`` and ``report``
    on it; a claim is released only by its outermost holder."""
    folder = tmp_path / "out"
    with writing(folder, "run"):
        with writing(folder, "posterior"):
            pass
        assert (folder / LOCK_FILE).exists()
    assert not (folder / LOCK_FILE).exists() and folder.is_dir()


# The same writer and a second process where neither fcntl nor msvcrt can be imported (a
# platform without flock): brdf_infer imports, and the lock file's record stands for the lock.
_NO_FLOCK = "import sys\nsys.modules['fcntl'] = sys.modules['msvcrt'] = None\n"
_SECOND = textwrap.dedent(
    """
    import sys
    from pathlib import Path
    import brdf_infer
    from brdf_infer._internal import oslock
    from brdf_infer._internal.outlock import LOCK_FILE, require_complete, writing
    from brdf_infer.errors import BadInputError

    assert oslock.BACKEND == "record", oslock.BACKEND
    folder = Path(sys.argv[1])
    try:
        require_complete(folder)
        with writing(folder, "run") as claim:
            print("took", claim.previous.pid if claim.previous else None)
        print("released", (folder / LOCK_FILE).exists())
    except BadInputError as error:
        print("refused", error)
    """
)


def _second_writer(folder) -> str:
    result = subprocess.run(
        [sys.executable, "-c", _NO_FLOCK + _SECOND, str(folder)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_without_fcntl_the_package_imports_and_the_record_is_the_lock(tmp_path):
    """Where ``fcntl`` is missing (Windows has msvcrt instead; this hides both), a live
    writer's folder is refused to a second writer and to readers, a dead writer's folder is
    taken over, and a finished writer leaves no lock file."""
    folder = tmp_path / "out"
    assert _second_writer(folder) == "took None\nreleased False\n"
    holder = subprocess.Popen(
        [sys.executable, "-c", _NO_FLOCK + _HOLDER, str(folder)], stdout=subprocess.PIPE, text=True
    )
    try:
        assert holder.stdout.readline().strip() == "held"
        out = _second_writer(folder)
        assert out.startswith("refused ") and "is being written by 'brdf-infer run'" in out
        assert f"process {holder.pid} on " in out
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
    out = _second_writer(folder)
    assert out.startswith("refused ") and "incomplete: 'brdf-infer run'" in out  # the reader
    with writing(folder, "run") as claim:  # this process (flock) takes it over too
        assert claim.previous.pid == holder.pid
    assert _second_writer(folder) == "took None\nreleased False\n"
