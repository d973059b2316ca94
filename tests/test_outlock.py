"""One writer per output folder; a folder a writer left incomplete is refused by every reader
and taken over by the next producer."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from brdf_infer._internal.atomic import atomic_write_json
from brdf_infer._internal.outlock import (
    ADDING_LOCK_FILE,
    LOCK_FILE,
    require_complete,
    shard_lock_file,
    writing,
)
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


@pytest.mark.full
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
        assert claim.previous["pid"] == holder.pid and claim.previous["command"] == "run"
        assert not (folder / ".summary.json.abcd1234.tmp").exists()  # the dead writer's
        assert (folder / "fit_lsq.json").exists()
        atomic_write_json(folder / "summary.json", {})
    require_complete(folder)
    assert not (folder / LOCK_FILE).exists()
    # an adder killed while adding (its lock file left) leaves the folder complete
    (folder / ADDING_LOCK_FILE).write_text(json.dumps({"pid": holder.pid, "command": "report"}))
    require_complete(folder)
    with writing(folder, "report", adds=True):
        assert json.loads((folder / ADDING_LOCK_FILE).read_text())["pid"] == os.getpid()
    assert not (folder / ADDING_LOCK_FILE).exists()
    require_complete(folder)


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


@pytest.mark.full
def test_a_shard_and_a_plain_writer_refuse_each_other_and_shards_share_a_folder(tmp_path):
    """The shards of a batch each hold their own marker: two shards write one folder side by
    side, a plain writer is refused while one runs (and refuses them), and a shard that died
    leaves the folder incomplete until a plain writer finishes it."""
    folder = tmp_path / "out"
    zero, one = shard_lock_file(0, 2), shard_lock_file(1, 2)
    with writing(folder, "batch --shard 0/2", marker=zero):
        out = _other(folder, "writing(folder, 'batch --shard 1/2', marker=shard_lock_file(1, 2))")
        assert out == "held\n"
        out = _other(folder, "writing(folder, 'batch')")
        assert out.startswith("refused ") and "'brdf-infer batch --shard 0/2' (process " in out
        atomic_write_json(folder / "a.json", {})
    assert not (folder / zero).exists()
    with writing(folder, "batch"):
        out = _other(folder, "writing(folder, 'batch --shard 1/2', marker=shard_lock_file(1, 2))")
        assert out.startswith("refused ") and "'brdf-infer batch' (process " in out
    (folder / one).write_text(json.dumps({"pid": 1, "command": "batch --shard 1/2"}))  # died
    with pytest.raises(BadInputError, match="incomplete: 'brdf-infer batch --shard 1/2'"):
        require_complete(folder)
    with writing(folder, "batch"):
        atomic_write_json(folder / "b.json", {})
    require_complete(folder)  # the plain writer finished the batch: the dead shard's marker went
    assert sorted(p.name for p in folder.iterdir()) == ["a.json", "b.json"]


_OTHER = textwrap.dedent(
    """
    import sys
    from pathlib import Path
    from brdf_infer._internal.outlock import shard_lock_file, writing
    from brdf_infer.errors import BadInputError

    folder = Path(sys.argv[1])
    try:
        with CLAIM:
            print("held")
    except BadInputError as error:
        print("refused", error)
    """
)


def _other(folder, claim: str) -> str:
    """``with CLAIM:`` in another process: ``held`` or ``refused <the error>``."""
    result = subprocess.run(
        [sys.executable, "-c", _OTHER.replace("CLAIM", claim), str(folder)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    return result.stdout


@pytest.mark.full
def test_without_fcntl_the_package_imports_and_the_marker_still_says_incomplete(tmp_path):
    """Where ``fcntl`` is missing (Windows): a writer warns that a second writer is not
    refused, a writer that stopped on an error after writing leaves the folder incomplete,
    and the next writer finishes it."""
    folder = tmp_path / "out"
    script = textwrap.dedent(
        """
        import sys, warnings
        from pathlib import Path
        from brdf_infer._internal.atomic import atomic_write_json
        from brdf_infer._internal.outlock import require_complete, writing
        from brdf_infer.errors import BadInputError

        folder = Path(sys.argv[1])
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                with writing(folder, "run"):
                    atomic_write_json(folder / "a.json", {})
                    raise RuntimeError("stopped")
            except RuntimeError:
                pass
        print(str(caught[0].message))
        try:
            require_complete(folder)
        except BadInputError as error:
            print(error)
        with warnings.catch_warnings(record=True):
            with writing(folder, "run"):
                pass
        require_complete(folder)
        print("complete")
        """
    )
    result = subprocess.run(
        [sys.executable, "-c", "import sys\nsys.modules['fcntl'] = None\n" + script, str(folder)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    warned, refused, complete = result.stdout.splitlines()
    assert warned == (
        f"{folder}: no file locks here (no fcntl on this platform): a second writer is not refused"
    )
    assert refused.startswith(f"{folder}: incomplete: 'brdf-infer run' (process ")
    assert refused.endswith("stopped before finishing it (RuntimeError); run that command again")
    assert complete == "complete"
