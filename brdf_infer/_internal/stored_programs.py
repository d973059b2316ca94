"""Traced programs kept on disk (``jax.export``), so that a warm run loads them instead of
tracing them again.

XLA's persistent compilation cache (:mod:`brdf_infer._internal.cache`) keeps compiled
programs, but JAX finds one only after tracing the Python function and lowering it: for
NumPyro's NUTS step on the bundled scene that is ≈ 2 s of every warm run (tracing 1.4 s and
lowering 0.6 s of the start and step programs, against 0.7 s of loading both from XLA's
cache). Here the traced program is serialised once with :mod:`jax.export` into
``<cache folder>/programs/<key>.jaxexport`` and a later run deserialises it; compiling it then
meets XLA's cache as before.

A stored program must never stand in for a different one, so its key is the SHA-256 of
everything that shapes it:

* the environment: the versions of Python, jax, jaxlib and NumPyro, JAX's backend and its
  float64 flag, and a digest of every source file of brdf_infer (any edit traces anew);
* the caller's ``identity``: the program's name and every value its Python closes over
  (:func:`canonical_bytes` of the model's scene, priors, flags and the sampler's settings,
  and the data's values);
* the arguments' tree structure, shapes and dtypes.

A file that cannot be read or deserialised, or whose arguments do not match, is traced anew and
replaced. Both paths compile the exported program, so a warm run's draws are those of a cold
run bit for bit. A program :mod:`jax.export` refuses — a tree type it cannot name, or a host
callback (lineax's checks in the least-squares solver) — is compiled as before and not stored;
an empty ``<key>.refused`` says so to later runs, which then trace it once, for ``jax.jit``,
instead of twice (≈ 1 s of every warm ``fit --method lsq`` on the bundled scene). Custom calls
without jax.export's compatibility guarantee (LAPACK's ``ormqr``) are stored: the key holds
the exact jaxlib version that reads them.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import sys
import threading
from collections.abc import Callable, Sequence
from enum import Enum
from importlib import metadata
from pathlib import Path
from typing import Any

import jax
import numpy as np
from jax import export

from brdf_infer._internal.atomic import atomic_write_bytes

PROGRAM_FOLDER = "programs"
SUFFIX = ".jaxexport"
# an empty file under the key of a program jax.export refused: the next run traces it for
# jit only, not for export first
REFUSED_SUFFIX = ".refused"
# custom calls without jax.export's compatibility guarantee across jaxlib versions (LAPACK's
# ormqr in the least-squares solver's QR) are allowed: the key holds the exact jaxlib
# version, so a stored program is only ever read by the jaxlib that wrote it
ANY_CUSTOM_CALL = (export.DisabledSafetyCheck.custom_call("ALL"),)
PACKAGE_ROOT = Path(__file__).resolve().parents[1]


class Unkeyable(TypeError):
    """A value whose text does not determine it (e.g. an object's default ``repr``)."""


def canonical_bytes(value: Any) -> bytes:
    """Bytes that determine ``value``: dataclasses, named tuples, mappings and sequences field
    by field, arrays by dtype, shape and every byte (never NumPy's abbreviated ``repr``),
    numbers, strings, paths and enums by ``repr``.

    Raises:
        Unkeyable: a value of another type (its text might not tell two values apart).
    """
    hasher = hashlib.sha256()
    _feed(hasher, value)
    return hasher.digest()


def _feed(hasher, value: Any) -> None:
    if value is None or isinstance(value, bool | int | float | complex | str | bytes | Path):
        hasher.update(f"{type(value).__name__}:{value!r};".encode())
    elif isinstance(value, Enum):
        hasher.update(f"enum:{type(value).__qualname__}.{value.name};".encode())
    elif isinstance(value, np.ndarray | np.generic | jax.Array):
        array = np.asarray(value)
        hasher.update(f"array:{array.dtype.str}:{array.shape};".encode())
        hasher.update(np.ascontiguousarray(array).tobytes())
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        hasher.update(f"dataclass:{type(value).__qualname__}(".encode())
        for field in dataclasses.fields(value):
            hasher.update(f"{field.name}=".encode())
            _feed(hasher, getattr(value, field.name))
        hasher.update(b")")
    elif isinstance(value, tuple) and hasattr(value, "_fields"):
        hasher.update(f"namedtuple:{type(value).__qualname__}".encode())
        _feed(hasher, value._asdict())
    elif isinstance(value, dict):
        hasher.update(b"dict{")
        for key in sorted(value, key=repr):
            _feed(hasher, key)
            _feed(hasher, value[key])
        hasher.update(b"}")
    elif isinstance(value, list | tuple | frozenset | set):
        items = sorted(value, key=repr) if isinstance(value, frozenset | set) else value
        hasher.update(f"{type(value).__name__}[".encode())
        for item in items:
            _feed(hasher, item)
        hasher.update(b"]")
    else:
        raise Unkeyable(f"cannot key a program on a {type(value).__qualname__}")


@functools.cache
def environment_digest() -> bytes:
    """The versions and the source digest every key holds (module docstring)."""
    hasher = hashlib.sha256()
    stamp = (  # the versions by their metadata: fit and tis import no NumPyro
        sys.version,
        *(metadata.version(package) for package in ("jax", "jaxlib", "numpyro")),
        jax.default_backend(),
        bool(jax.config.jax_enable_x64),
    )
    hasher.update(repr(stamp).encode())
    for source in sorted(PACKAGE_ROOT.rglob("*.py")):
        hasher.update(source.relative_to(PACKAGE_ROOT).as_posix().encode())
        hasher.update(source.read_bytes())
    return hasher.digest()


def program_key(identity: bytes, arguments: Sequence[Any]) -> str:
    """The key of a program of ``identity`` over ``arguments`` (module docstring)."""
    leaves, treedef = jax.tree_util.tree_flatten(tuple(arguments))
    shapes = [(shape, dtype.str) for shape, dtype in map(_shape_dtype, leaves)]
    hasher = hashlib.sha256(environment_digest())
    hasher.update(identity)
    hasher.update(repr((str(treedef), shapes)).encode())
    return hasher.hexdigest()


def register_tree_types(types: Sequence[type]) -> None:
    """Let :mod:`jax.export` serialise these named tuples (by module and qualified name);
    registering one twice is harmless."""
    for kind in types:
        with contextlib.suppress(ValueError):  # already registered
            export.register_namedtuple_serialization(
                kind, serialized_name=f"{kind.__module__}.{kind.__qualname__}"
            )


def compile_stored(
    function: Callable,
    arguments: Sequence[Any],
    *,
    identity: bytes,
    compiler_options: dict | None = None,
    folder: Path | None = None,
) -> Callable:
    """``function`` compiled for ``arguments``: loaded from its stored export when there is
    one under its key (no tracing), else traced, exported, stored and compiled.

    Args:
        function: the program (jax-traceable).
        arguments: example arguments (their tree, shapes and dtypes are the program's).
        identity: what the program closes over (its name, :func:`canonical_bytes` of its
            constants); two programs of the same identity and arguments' shapes must be the
            same program.
        compiler_options: XLA options of the compilation.
        folder: where programs are kept (default ``programs/`` in the compilation cache's
            folder; none when that cache is off: then traced every time).
    """
    folder = _folder() if folder is None else folder
    if folder is None:
        return jax.jit(function).lower(*arguments).compile(compiler_options)
    path = folder / f"{program_key(identity, arguments)}{SUFFIX}"
    refused = path.with_suffix(REFUSED_SUFFIX)
    exported = (
        None if refused.is_file() else _load(path, arguments) or _export(function, arguments, path)
    )
    if exported is None:
        return jax.jit(function).lower(*arguments).compile(compiler_options)
    return jax.jit(exported.call).lower(*arguments).compile(compiler_options)


def _export(function: Callable, arguments: Sequence[Any], path: Path) -> export.Exported | None:
    """``function`` traced and exported, stored at ``path``; None, and the refusal marked
    beside it, where jax.export refuses it."""
    try:
        exported = export.export(jax.jit(function), disabled_checks=ANY_CUSTOM_CALL)(*arguments)
        serialised = bytes(exported.serialize())
    except (ValueError, NotImplementedError):  # export refuses it: compiled, not stored
        exported, serialised = None, b""
    with contextlib.suppress(OSError):  # a read-only cache: traced again next time
        atomic_write_bytes(
            path if exported is not None else path.with_suffix(REFUSED_SUFFIX), serialised
        )
    return exported


def _folder() -> Path | None:
    """``programs/`` in the compilation cache's folder; None when that cache is off."""
    cache = jax.config.jax_compilation_cache_dir
    if not jax.config.jax_enable_compilation_cache or not cache:
        return None
    return Path(cache) / PROGRAM_FOLDER


def _load(path: Path, arguments: Sequence[Any]) -> export.Exported | None:
    """The stored program at ``path`` if it reads and takes ``arguments``, else None."""
    try:
        exported = export.deserialize(bytearray(path.read_bytes()))
    except Exception:  # missing, cut short by a killed writer, or from another format
        return None
    leaves, treedef = jax.tree_util.tree_flatten((tuple(arguments), {}))
    shapes = [_shape_dtype(leaf) for leaf in leaves]
    if exported.in_tree != treedef or [(a.shape, a.dtype) for a in exported.in_avals] != shapes:
        return None
    return exported


def _shape_dtype(leaf) -> tuple[tuple[int, ...], np.dtype]:
    dtype = leaf.dtype if hasattr(leaf, "dtype") else np.result_type(leaf)
    return tuple(np.shape(leaf)), np.dtype(dtype)


class StoredFunction:
    """``function`` compiled once per tree and shapes of its arguments by
    :func:`compile_stored`: a drop-in for ``jax.jit(function)`` whose warm runs load the
    traced program. ``identity``: the values ``function`` closes over (with a name that
    tells it from other programs), keyed by :func:`canonical_bytes`; an :class:`Unkeyable`
    one leaves the function traced every run."""

    def __init__(self, function: Callable, identity: Any, compiler_options: dict | None = None):
        self._function = function
        self._identity = identity
        self._options = compiler_options
        self._compiled: dict = {}
        self._lock = threading.Lock()

    def __call__(self, *arguments):
        return self.compiled(*arguments)(*arguments)

    def compiled(self, *arguments) -> Callable:
        """The compiled program for arguments of these shapes (loaded, or traced once)."""
        leaves, treedef = jax.tree_util.tree_flatten(arguments)
        key = (treedef, tuple(map(_shape_dtype, leaves)))
        with self._lock:
            if key not in self._compiled:
                self._compiled[key] = self._build(arguments)
            return self._compiled[key]

    def _build(self, arguments: tuple) -> Callable:
        try:
            identity = canonical_bytes(self._identity)
        except Unkeyable:
            return jax.jit(self._function).lower(*arguments).compile(self._options)
        return compile_stored(
            self._function, arguments, identity=identity, compiler_options=self._options
        )
