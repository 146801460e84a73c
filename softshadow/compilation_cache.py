"""JAX's persistent compilation cache for softshadow's processes (the CLI, Dask workers, library fits).

Compilation dominates short runs on a small machine: with the cache on, a second run or a
second worker process loads the compiled solvers and renderers instead of compiling them.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["default_cache_dir", "use_compilation_cache", "SAVED_PROGRAMS_ENV"]

#: The folder where ``fitting.solve.saved_programs`` keeps traced programs (``jax.export``); unset: off.
SAVED_PROGRAMS_ENV = "SOFTSHADOW_SAVED_PROGRAMS"


#: Programs that compile faster than this (seconds) are not kept: loading one costs about as much.
#: A higher floor leaves out programs that every new process would compile again (``--lod
#: auto``'s shading of the samples at every k compiles in about half a second).
MIN_COMPILE_SECONDS = 0.1


#: The environment variable that moves the caches (a folder) or turns them off (``off``).
CACHE_ENV = "SOFTSHADOW_JAX_CACHE"


def default_cache_dir() -> Path | None:
    """``SOFTSHADOW_JAX_CACHE`` when set, else ``~/.cache/softshadow/jax``; None when it is ``off``."""
    value = os.environ.get(CACHE_ENV)
    if value is not None and value.strip().lower() == "off":
        return None
    return Path(value) if value else Path.home() / ".cache" / "softshadow" / "jax"


def use_compilation_cache(cache_dir=None) -> None:
    """Turn on JAX's persistent compilation cache in this process, in ``cache_dir``
    (``default_cache_dir()`` when None; nothing when that is off). The command line, Dask's
    workers and the fitter's entry points (``fitting.fit_folder``, ``fitting.fit_photos``) call
    it. Programs that compile in under ``MIN_COMPILE_SECONDS`` are not kept. A folder that cannot
    be created leaves the cache off (never an error). Also turns on saved traced programs
    (``SAVED_PROGRAMS_ENV``, in the folder ``programs`` inside it) unless that variable is
    already set: the compilation cache's key is the traced program, so without them every
    process still traces the solver.

    JAX is not imported here: importing it takes seconds, and a process that never needs it (a
    photo without geometry) should not pay for it. If JAX is not loaded yet, the settings go
    into JAX's environment variables, which JAX reads when it is first imported (and which
    processes started from this one inherit); if it is, they go into its config."""
    cache = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    if cache is None:
        return
    try:
        cache.mkdir(parents=True, exist_ok=True)
    except OSError:
        return
    os.environ.setdefault(SAVED_PROGRAMS_ENV, str(cache / "programs"))
    settings = {"jax_compilation_cache_dir": str(cache), "jax_persistent_cache_min_compile_time_secs": MIN_COMPILE_SECONDS}
    jax = sys.modules.get("jax")
    for name, value in settings.items():
        if jax is not None:
            jax.config.update(name, value)
        else:
            os.environ[name.upper()] = str(value)
