"""Programs saved with ``jax.export``, so that a new process skips tracing them (JAX).

Tracing and lowering the fitter's solver (Levenberg-Marquardt around the penumbra model, with
its forward-mode Jacobian) takes most of a short ``softshadow fit``: about 7 s of the first
fit's 11 s on a 2-core machine. JAX's persistent compilation cache only skips the compilation
that follows, because its key is the traced program. Here the traced program itself is kept:
``call_saved`` exports it (StableHLO, ``jax.export``) on first use and writes it to a folder;
a later process with the same inputs' shapes, static choices, package source and JAX version
loads it and compiles it (from the compilation cache too) without tracing Python.

Off unless a folder is set (``SOFTSHADOW_SAVED_PROGRAMS``): ``softshadow.use_compilation_cache``, which the
command line and the fitter's entry points (``fitting.fit_folder``, ``fitting.fit_photos``) call, sets it next to
the compilation cache; ``SOFTSHADOW_JAX_CACHE=off`` leaves both off. Any failure to export, save or load falls back to the traced call.
"""

from __future__ import annotations

import functools
import hashlib
import os
import re
import tempfile
from importlib import metadata
from pathlib import Path

import equinox as eqx
import jax
import numpy as np
from softshadow.internal import SAVED_PROGRAMS_ENV

__all__ = ["call_saved", "saved_programs_dir"]

# LAPACK targets of the solver's linear algebra that jax.export does not guarantee across versions.
_UNGUARANTEED = tuple(f"lapack_{t}ormqr_ffi" for t in "sd") + tuple(f"lapack_{t}unmqr_ffi" for t in "cz")

# Loaded (or freshly exported) programs of this process, by key; keys whose export failed.
_LOADED: dict[str, object] = {}
_FAILED: set[str] = set()


def saved_programs_dir() -> Path | None:
    """The folder of saved programs (``SOFTSHADOW_SAVED_PROGRAMS``), or None: saving is off."""
    value = os.environ.get(SAVED_PROGRAMS_ENV)
    return Path(value) if value else None


@functools.lru_cache(maxsize=1)
def _source_digest() -> str:
    """A digest of the source of every module a saved program can be traced from (softshadow
    and fitting) and of the versions of the libraries it is traced through: a program saved by
    other code is never loaded."""
    h = hashlib.sha256()
    for name in ("jax", "jaxlib", "equinox", "optimistix", "lineax", "numpy"):
        try:
            h.update(f"{name}={metadata.version(name)};".encode())
        except metadata.PackageNotFoundError:
            h.update(f"{name}=none;".encode())
    for package in ("softshadow", "fitting"):
        root = Path(__import__(package).__file__).parent
        for path in sorted(root.rglob("*.py")):
            h.update(path.relative_to(root).as_posix().encode())
            h.update(path.read_bytes())
    return h.hexdigest()


def _key(name: str, treedef, static_def, static_leaves, leaves) -> str | None:
    """The program's key, or None when some static part prints by its address (a key that
    would differ in every process) or abridged (a large array: two values could share it)."""
    text = "|".join([name, _source_digest(), jax.__version__, jax.default_backend(),
                     str(jax.dtypes.canonicalize_dtype(np.float64)), str(treedef), str(static_def),
                     repr(static_leaves), repr([(tuple(x.shape), str(x.dtype)) for x in leaves])])
    if " at 0x" in text or "..." in text:
        return None
    return hashlib.sha256(text.encode()).hexdigest()[:32]


def _write_atomically(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def call_saved(name: str, fn, *args) -> tuple:
    """``fn(*args)`` (jitted), through a saved program when saving is on.

    fn: a pure function of pytrees whose array leaves are its inputs (other leaves are static
    and part of the key) and which returns a tuple of arrays. name: a stable name for fn.
    Returns the tuple of arrays. A program is keyed by name, the inputs' structure, shapes and
    dtypes, the static leaves, the package source's digest, the JAX version and backend.
    """
    directory = saved_programs_dir()
    if directory is None:
        return _jitted(fn)(*args)
    dynamic, static = eqx.partition(args, eqx.is_array)
    leaves, treedef = jax.tree_util.tree_flatten(dynamic)
    static_leaves, static_def = jax.tree_util.tree_flatten(static)
    key = _key(name, treedef, static_def, static_leaves, leaves)
    if key is None or key in _FAILED:
        return _jitted(fn)(*args)
    program = _LOADED.get(key)
    if program is None:
        program = _load_or_export(directory / f"{name}-{key}.jaxexport", fn, treedef, static, leaves)
        if program is None:
            _FAILED.add(key)
            return _jitted(fn)(*args)
        _LOADED[key] = program
    return tuple(program(*leaves))


@functools.cache
def _jitted(fn):
    return eqx.filter_jit(fn)


def _load_or_export(path: Path, fn, treedef, static, leaves):
    """A jitted call of the program saved at ``path``, exporting and saving it first when it is
    not there; None when it can be neither loaded nor exported."""
    from jax import export
    try:
        exported = export.deserialize(bytearray(path.read_bytes()))
    except Exception:  # noqa: BLE001 -- missing, unreadable or from another version: export anew
        exported = None
    if exported is None:
        def flat(*flat_leaves):
            return tuple(fn(*eqx.combine(jax.tree_util.tree_unflatten(treedef, flat_leaves), static)))

        specs = [jax.ShapeDtypeStruct(x.shape, x.dtype) for x in leaves]
        # Custom calls without JAX's cross-version guarantee (LAPACK's ormqr, in the solver's QR)
        # are safe here: a program is only loaded by the JAX version and backend that saved it.
        unchecked = set(_UNGUARANTEED)
        exported = None
        for _ in range(2):
            checks = [export.DisabledSafetyCheck.custom_call(t) for t in sorted(unchecked)]
            try:
                exported = export.export(jax.jit(flat), disabled_checks=checks)(*specs)
                break
            except ValueError as exc:  # another such target: name it and try once more
                more = set(re.findall(r"custom_call @(\w+)\(", str(exc))) - unchecked
                if not more:
                    return None
                unchecked |= more
            except Exception:  # noqa: BLE001 -- a program JAX cannot export is traced as usual
                return None
        if exported is None:
            return None
        try:
            _write_atomically(path, bytes(exported.serialize()))
        except Exception:  # noqa: BLE001 -- e.g. a read-only folder: this process still uses it
            pass
    return jax.jit(exported.call)
