"""The old import paths of the moved modules (``brdf_infer/_moved.py``): every one still imports,
as the same module object as its new path, and warns once with FutureWarning naming the new path."""

import importlib
import subprocess
import sys
import textwrap
import warnings

import pytest

import brdf_infer
from brdf_infer import _moved


def _forget(monkeypatch, old: str) -> None:
    """As if the old path had never been imported in this process (restored afterwards)."""
    monkeypatch.delitem(sys.modules, old, raising=False)
    if old.rpartition(".")[2] in vars(brdf_infer):  # not hasattr: that would import it
        monkeypatch.delattr(brdf_infer, old.rpartition(".")[2])


@pytest.mark.parametrize("old", sorted(_moved.MOVED))
def test_an_old_module_path_imports_the_new_module_and_warns(monkeypatch, old):
    new = importlib.import_module(_moved.MOVED[old])
    _forget(monkeypatch, old)
    with pytest.warns(FutureWarning, match=rf"{old} moved to {_moved.MOVED[old]}") as caught:
        module = importlib.import_module(old)
    assert module is new and sys.modules[old] is new
    assert new.__spec__.name == new.__name__ == _moved.MOVED[old]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert importlib.import_module(old) is new  # once per process
    assert len(caught) == 1


@pytest.mark.parametrize("old", sorted(_moved.MOVED))
def test_from_the_package_import_an_old_name_warns_at_the_callers_line(monkeypatch, old):
    new = importlib.import_module(_moved.MOVED[old])
    _forget(monkeypatch, old)
    name = old.rpartition(".")[2]
    with pytest.warns(FutureWarning, match="the old path goes in the next release") as caught:
        exec(f"from brdf_infer import {name} as found", namespace := {})
    assert namespace["found"] is new
    assert caught[0].filename == "<string>"  # the importing line, not the import machinery


def test_old_paths_work_in_a_fresh_process_in_every_form():
    """`import a.b`, `from a.b import x`, `from a import b`: each first use warns; one module."""
    script = textwrap.dedent(
        """
        import importlib, sys, warnings
        warnings.simplefilter("always")
        from brdf_infer._moved import MOVED
        for i, (old, new) in enumerate(sorted(MOVED.items())):
            short, form = old.rpartition(".")[2], i % 3
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                if form == 0:
                    exec(f"import {old}")
                    found = sys.modules[old]
                elif form == 1:
                    exec(f"from {old} import __name__ as name")
                    found = sys.modules[old]
                else:
                    found = getattr(__import__("brdf_infer", fromlist=[short]), short)
            assert found is importlib.import_module(new), old
            futures = [w for w in caught if issubclass(w.category, FutureWarning)]
            assert len(futures) == 1 and new in str(futures[0].message), (old, caught)
        print("ok", len(MOVED))
        """
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["ok", str(len(_moved.MOVED))]


def test_every_new_path_exists_and_no_old_file_is_left():
    for old, new in _moved.MOVED.items():
        assert importlib.util.find_spec(new) is not None, new
        assert importlib.util.find_spec(new).name == new
        relative = old.split(".")[1:]
        path = brdf_infer.__path__[0]
        assert not any(
            __import__("pathlib").Path(path, *relative[:-1], f"{relative[-1]}{suffix}").exists()
            for suffix in (".py", "")
        ), f"{old} is both moved and still a file"


def test_a_moved_entry_pointing_nowhere_fails_clearly(monkeypatch):
    monkeypatch.setitem(_moved.MOVED, "brdf_infer.planted_gone", "brdf_infer.fit.planted_missing")
    _forget(monkeypatch, "brdf_infer.planted_gone")
    with pytest.raises(
        ModuleNotFoundError, match=r"planted_gone moved to brdf_infer\.fit\.planted_missing"
    ):
        importlib.import_module("brdf_infer.planted_gone")
    assert "brdf_infer.planted_gone" not in sys.modules


def test_an_unknown_name_is_still_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'not_a_module'"):
        brdf_infer.not_a_module  # noqa: B018
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("brdf_infer.not_a_module")


def test_a_module_inside_a_moved_package_is_the_new_module_not_a_second_copy():
    """`brdf_infer.raytrace` moved as a package: its modules' old names give the new modules
    (one class object, so isinstance holds across the names), each warning once."""
    script = textwrap.dedent(
        """
        import warnings
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            import brdf_infer.raytrace._trace as old
        import brdf_infer.studies.raytrace._trace as new
        assert old is new, (old, new)
        import brdf_infer.workflow.batch._team as team
        with warnings.catch_warnings(record=True) as more:
            warnings.simplefilter("always")
            from brdf_infer.batch import _team
        assert _team is team
        moved = [str(w.message) for w in caught + more if w.category is FutureWarning]
        assert any("brdf_infer.raytrace._trace moved to" in m for m in moved), moved
        from brdf_infer._moved import new_name
        assert new_name("brdf_infer.exportx") is None  # a prefix that is not a package's
        print("ok")
        """
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr
