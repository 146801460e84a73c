"""numba for compiled loops that run on several threads (``parallel=True``, ``prange``).

numba runs them on OpenMP here (its ``omp`` threading layer), whose idle threads by default
spin for a while after each loop before they sleep. On a small, shared machine that spinning
takes the cores from the renderer's other thread and from other processes: measured on the
2-core test machine at load ~4, a scene frame took twice the CPU time and twice the wall time.
``OMP_WAIT_POLICY=PASSIVE`` (unless already set) makes them sleep at once. OpenMP reads it when
it is loaded, which numba does at the first parallel loop, so every factory of a parallel loop
gets numba from here. A loop's helpers are ``loop_helper``s, so that numba's cache holds the loop
from one process to the next (see there).
"""

from __future__ import annotations

import os

__all__ = ["loop_helper", "parallel_numba"]


def parallel_numba():
    """The numba module, with OpenMP's idle threads set to sleep rather than spin (see above)."""
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    import numba
    return numba


def loop_helper(fn=None, *, inline: bool = False):
    """fn as a helper of compiled loops: a plain function that numba compiles into each loop that
    calls it (``numba.extending.register_jitable``), inlined there if ``inline``.

    Not a dispatcher of its own (``numba.njit``): numba keys a cached loop by its closure's
    contents, pickled, and a dispatcher pickles with an identifier drawn anew in every process, so
    a loop that closed over one missed its cache in every new process (compiled again, up to
    seconds each, and its cache folder one entry larger). Use as ``@loop_helper`` or
    ``@loop_helper(inline=True)``.
    """
    parallel_numba()
    from numba.extending import register_jitable

    wrap = register_jitable(inline="always" if inline else "never")
    return wrap if fn is None else wrap(fn)
