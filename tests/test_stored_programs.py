"""Traced programs kept on disk (brdf_infer._internal.stored_programs): a warm run loads them
without tracing, and a changed constant, version or argument shape never loads a stale one."""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

from brdf_infer._internal import stored_programs
from brdf_infer._internal.stored_programs import (
    Unkeyable,
    canonical_bytes,
    compile_stored,
    program_key,
)


def _scaled(constant: float):
    """A program that closes over ``constant`` (as a scene's prior would)."""
    return lambda x: jnp.sin(x) * constant


def _no_tracing(monkeypatch) -> None:
    def refuse(*_, **__):
        raise AssertionError("traced, though a stored program was expected")

    monkeypatch.setattr(stored_programs.export, "export", refuse)


def _program(folder, constant: float, x):
    return compile_stored(
        _scaled(constant), (x,), identity=canonical_bytes(("scaled", constant)), folder=folder
    )


def test_a_stored_program_loads_without_tracing_and_computes_the_same(tmp_path, monkeypatch):
    x = jnp.linspace(0.0, 1.0, 5)
    first = np.asarray(_program(tmp_path, 2.0, x)(x))
    assert len(list(tmp_path.glob(f"*{stored_programs.SUFFIX}"))) == 1
    _no_tracing(monkeypatch)
    again = np.asarray(_program(tmp_path, 2.0, x)(x))
    np.testing.assert_array_equal(again, first)
    np.testing.assert_allclose(first, 2.0 * np.sin(np.asarray(x)), rtol=1e-15)


def test_a_changed_constant_is_traced_anew_not_loaded_stale(tmp_path):
    x = jnp.linspace(0.0, 1.0, 5)
    _program(tmp_path, 2.0, x)
    changed = np.asarray(_program(tmp_path, 3.0, x)(x))
    np.testing.assert_allclose(changed, 3.0 * np.sin(np.asarray(x)), rtol=1e-15)
    assert len(list(tmp_path.glob(f"*{stored_programs.SUFFIX}"))) == 2


def test_a_changed_version_or_source_is_traced_anew(tmp_path, monkeypatch):
    x = jnp.linspace(0.0, 1.0, 5)
    _program(tmp_path, 2.0, x)
    key = program_key(canonical_bytes(("scaled", 2.0)), (x,))
    monkeypatch.setattr(stored_programs, "environment_digest", lambda: b"jax 99.0")
    assert program_key(canonical_bytes(("scaled", 2.0)), (x,)) != key
    np.testing.assert_allclose(_program(tmp_path, 2.0, x)(x), 2.0 * np.sin(x), rtol=1e-15)
    assert len(list(tmp_path.glob(f"*{stored_programs.SUFFIX}"))) == 2


def test_planted_fault_an_identity_without_the_constant_loads_a_stale_program(tmp_path):
    """The key is the only guard: an identity that leaves out a constant the program closes
    over loads the other constant's program (hence model_identity holds every value)."""
    x = jnp.linspace(0.0, 1.0, 5)
    compile_stored(_scaled(2.0), (x,), identity=b"scaled", folder=tmp_path)
    stale = compile_stored(_scaled(3.0), (x,), identity=b"scaled", folder=tmp_path)
    np.testing.assert_allclose(stale(x), 2.0 * np.sin(x), rtol=1e-15)


def test_other_shapes_and_a_cut_file_are_traced_anew(tmp_path):
    x = jnp.linspace(0.0, 1.0, 5)
    _program(tmp_path, 2.0, x)
    longer = jnp.linspace(0.0, 1.0, 7)
    np.testing.assert_allclose(_program(tmp_path, 2.0, longer)(longer), 2.0 * np.sin(longer))
    for path in tmp_path.glob(f"*{stored_programs.SUFFIX}"):
        path.write_bytes(path.read_bytes()[:100])  # a writer killed halfway
    np.testing.assert_allclose(_program(tmp_path, 2.0, x)(x), 2.0 * np.sin(x), rtol=1e-15)


@dataclasses.dataclass(frozen=True)
class _Settings:
    scale: float
    weights: np.ndarray


def test_canonical_bytes_tells_apart_what_reprs_abbreviate():
    weights = np.zeros(5000)
    changed = weights.copy()
    changed[2500] = 1e-12  # NumPy's repr of both shows "0., 0., 0., ..., 0., 0., 0."
    assert repr(weights) == repr(changed)
    assert canonical_bytes(_Settings(1.0, weights)) != canonical_bytes(_Settings(1.0, changed))
    assert canonical_bytes({"a": 1, "b": 2.0}) == canonical_bytes({"b": 2.0, "a": 1})
    assert canonical_bytes((1, 2)) != canonical_bytes([1, 2])
    assert canonical_bytes(1) != canonical_bytes(1.0) != canonical_bytes(True)
    with pytest.raises(Unkeyable):
        canonical_bytes(object())


def _lya_model(**prior_changes):
    from brdf_infer.posterior._run import build_model
    from brdf_infer.scene import load_scene

    scene = load_scene("lya")
    priors = dict(scene.priors)
    for name, scale in prior_changes.items():
        priors[name] = dataclasses.replace(priors[name], scale=scale)
    scene = dataclasses.replace(scene, priors=priors)
    return build_model(scene, scene.load_measurements(), scene.model.family)


def test_the_model_identity_holds_the_priors_and_the_rows():
    from brdf_infer.posterior._model import model_identity

    model = _lya_model()
    same = canonical_bytes(model_identity(_lya_model()))
    assert canonical_bytes(model_identity(model)) == same
    assert canonical_bytes(model_identity(_lya_model(alpha=1.5))) != same
    rows = model.data.rows
    moved = model.data._replace(
        rows=rows._replace(log_reflectance=rows.log_reflectance.at[3].add(1e-9))
    )
    assert canonical_bytes(model_identity(dataclasses.replace(model, data=moved))) != same


@pytest.mark.full
def test_a_warm_nuts_program_is_loaded_and_draws_what_the_traced_one_drew(tmp_path, monkeypatch):
    from brdf_infer.posterior._nuts import NutsProgram, chain_keys

    monkeypatch.setattr(stored_programs, "_folder", lambda: tmp_path)
    model = _lya_model()
    keys = chain_keys(0, 1, 2)[0]
    traced = NutsProgram(model, warmup=30).run(model.data, keys, 20, workers=1)
    assert len(list(tmp_path.glob(f"*{stored_programs.SUFFIX}"))) == 3  # start, steps, constrain
    _no_tracing(monkeypatch)
    loaded = NutsProgram(model, warmup=30).run(model.data, keys, 20, workers=1)
    for name, values in traced.sites.items():
        np.testing.assert_array_equal(loaded.sites[name], values)
    changed = _lya_model(alpha=1.5)
    with pytest.raises(AssertionError, match="traced"):  # another prior: not the stored one
        NutsProgram(changed, warmup=30).run(changed.data, keys, 20, workers=1)


def test_a_stored_function_compiles_once_per_shape_and_loads_warm(tmp_path, monkeypatch):
    from brdf_infer._internal.stored_programs import StoredFunction

    monkeypatch.setattr(stored_programs, "_folder", lambda: tmp_path)
    x, longer = jnp.linspace(0.0, 1.0, 5), jnp.linspace(0.0, 1.0, 7)
    function = StoredFunction(_scaled(2.0), ("scaled", 2.0))
    np.testing.assert_allclose(function(x), 2.0 * np.sin(x), rtol=1e-15)
    np.testing.assert_allclose(function(longer), 2.0 * np.sin(longer), rtol=1e-15)
    assert function.compiled(x) is function.compiled(x)
    assert len(list(tmp_path.glob(f"*{stored_programs.SUFFIX}"))) == 2
    _no_tracing(monkeypatch)
    warm = StoredFunction(_scaled(2.0), ("scaled", 2.0))
    np.testing.assert_allclose(warm(longer), 2.0 * np.sin(longer), rtol=1e-15)
    with pytest.raises(AssertionError, match="traced"):
        StoredFunction(_scaled(3.0), ("scaled", 3.0))(x)


def test_a_program_export_refuses_is_compiled_not_stored_and_not_exported_again(
    tmp_path, monkeypatch
):
    """lineax's checks are host callbacks, which jax.export refuses: the program is compiled,
    not stored, and the refusal is remembered, so the next compilation traces it for jit only
    (export.export patched to fail)."""
    import lineax

    matrix = jnp.asarray(np.random.default_rng(0).normal(size=(6, 3)))
    target = matrix @ jnp.array([1.0, -2.0, 0.5])

    def solve(a, b):
        return lineax.linear_solve(lineax.MatrixLinearOperator(a), b, lineax.QR()).value

    program = compile_stored(solve, (matrix, target), identity=b"qr", folder=tmp_path)
    np.testing.assert_allclose(program(matrix, target), [1.0, -2.0, 0.5], atol=1e-12)
    assert not list(tmp_path.glob(f"*{stored_programs.SUFFIX}"))
    assert len(list(tmp_path.glob(f"*{stored_programs.REFUSED_SUFFIX}"))) == 1
    _no_tracing(monkeypatch)
    again = compile_stored(solve, (matrix, target), identity=b"qr", folder=tmp_path)
    np.testing.assert_allclose(again(matrix, target), [1.0, -2.0, 0.5], atol=1e-12)


def test_a_lapack_call_without_a_compatibility_guarantee_is_stored(tmp_path, monkeypatch):
    """LAPACK's ``ormqr`` (a QR's Q applied, as in the least-squares solver) has no
    jax.export compatibility guarantee across jaxlib versions; the key holds the version, so
    it is stored and loaded without tracing."""

    from jax.lax.linalg import ormqr

    def project(a, b):
        reflectors, taus = jnp.linalg.qr(a, mode="raw")
        return ormqr(reflectors.mT, taus, b[:, None])[:, 0]  # Q b

    matrix = jnp.asarray(np.random.default_rng(1).normal(size=(6, 3)))
    target = jnp.arange(6.0)
    expected = compile_stored(project, (matrix, target), identity=b"ormqr", folder=tmp_path)(
        matrix, target
    )
    assert len(list(tmp_path.glob(f"*{stored_programs.SUFFIX}"))) == 1
    _no_tracing(monkeypatch)
    loaded = compile_stored(project, (matrix, target), identity=b"ormqr", folder=tmp_path)
    np.testing.assert_array_equal(loaded(matrix, target), expected)


@pytest.mark.full
def test_a_loaded_start_with_a_traced_step_program_samples(tmp_path, monkeypatch):
    """A start program stored without its step program (another process stored one and not
    yet the other): the step program is traced though NumPyro's init_kernel never ran here."""
    from brdf_infer.posterior._nuts import NutsProgram, chain_keys

    monkeypatch.setattr(stored_programs, "_folder", lambda: tmp_path)
    model = _lya_model()
    keys = chain_keys(0, 1, 1)[0]
    traced = NutsProgram(model, warmup=30).run(model.data, keys, 20, workers=1)
    files = sorted(tmp_path.glob(f"*{stored_programs.SUFFIX}"), key=lambda p: p.stat().st_mtime)
    files[1].unlink()  # the step program (stored after the start program)
    again = NutsProgram(model, warmup=30).run(model.data, keys, 20, workers=1)
    for name, values in traced.sites.items():
        np.testing.assert_array_equal(again.sites[name], values)


def test_the_draws_likelihood_parts_are_stored_and_load_without_tracing(tmp_path, monkeypatch):
    """The program of every draw's likelihood parts takes the noise scales and returns the
    parts, named tuples jax.export must know: without their registration it refused the
    program in every run (a ``.refused`` marker, traced each time)."""
    from brdf_infer.model.error_model import NoiseScales
    from brdf_infer.posterior._likelihood import drawn_noise_scales

    monkeypatch.setattr(stored_programs, "_folder", lambda: tmp_path)
    model = _lya_model()
    count = 3
    physical = {name: jnp.full(count, 1.0) for name in model.family.parameters}
    sites = {**physical, "alpha": jnp.full(count, 3.0), "sample_sd": jnp.full(count, 0.05)}
    sites["repeatability"] = jnp.full(count, 0.03)
    scales = drawn_noise_scales(model.errors, model.data.noise, sites, count)
    assert isinstance(scales, NoiseScales)
    parts = model.draw_parts(sites)
    assert not list(tmp_path.glob(f"*{stored_programs.REFUSED_SUFFIX}"))
    assert len(list(tmp_path.glob(f"*{stored_programs.SUFFIX}"))) == 1
    _no_tracing(monkeypatch)
    again = _lya_model().draw_parts(sites)
    for loaded, traced in zip(again, parts, strict=True):
        np.testing.assert_array_equal(loaded, traced)
