"""JAX's persistent compilation cache for softshadow's processes (the CLI, Dask workers).

Compilation dominates short runs on a small machine: with the cache on, a second run or a
second worker process loads the compiled solvers and renderers instead of compiling them.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["default_cache_dir", "use_compilation_cache"]


def default_cache_dir() -> Path:
    """``SOFTSHADOW_JAX_CACHE`` when set, else ``~/.cache/softshadow/jax``."""
    return Path(os.environ.get("SOFTSHADOW_JAX_CACHE", Path.home() / ".cache" / "softshadow" / "jax"))


def use_compilation_cache(cache_dir=None) -> None:
    """Turn on JAX's persistent compilation cache in this process, in ``cache_dir``
    (``default_cache_dir()`` when None). Programs that compile in under 0.5 s are not
    kept. A folder that cannot be created leaves the cache off (never an error)."""
    import jax
    cache = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    try:
        cache.mkdir(parents=True, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", str(cache))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    except OSError:
        pass
