"""numba for compiled loops that run on several threads (``parallel=True``, ``prange``).

numba runs them on OpenMP here (its ``omp`` threading layer), whose idle threads by default
spin for a while after each loop before they sleep. On a small, shared machine that spinning
takes the cores from the renderer's other thread and from other processes: measured on the
2-core test machine at load ~4, a scene frame took twice the CPU time and twice the wall time.
``OMP_WAIT_POLICY=PASSIVE`` (unless already set) makes them sleep at once. OpenMP reads it when
numba starts its threads, at the first parallel loop of the process, whoever runs it: so
``import softshadow`` sets it (``sleep_idle_threads``), and warns when numba's OpenMP threads
started before without it. Every factory of a parallel loop gets numba from ``parallel_numba``.
A loop's helpers are ``loop_helper``s, so that numba's cache holds the loop from one process to
the next (see there).
"""

from __future__ import annotations

import os
import sys
import warnings

__all__ = ["loop_helper", "parallel_numba", "sleep_idle_threads"]


def sleep_idle_threads() -> None:
    """Sets ``OMP_WAIT_POLICY=PASSIVE`` unless it is set; warns (``RuntimeWarning``) when numba's
    OpenMP threads already run without it: they spin after each loop, and OpenMP does not read the
    setting again (a scene frame then took 1.5 times as long on the 2-core test machine)."""
    if "OMP_WAIT_POLICY" in os.environ:
        return
    parallel = sys.modules.get("numba.np.ufunc.parallel")  # loaded, not imported here: numba is slow to import
    if getattr(parallel, "_is_initialized", False) and sys.modules["numba"].threading_layer() == "omp":
        warnings.warn("numba's OpenMP threads started before softshadow was imported, without OMP_WAIT_POLICY: "
                      "they spin after each parallel loop and slow softshadow's loops (import softshadow first, or "
                      "set OMP_WAIT_POLICY=PASSIVE in the environment)", RuntimeWarning, stacklevel=2)
    os.environ["OMP_WAIT_POLICY"] = "PASSIVE"


def parallel_numba():
    """The numba module, for the parallel loops (their idle threads set to sleep by ``import
    softshadow``, which runs before any of this package's modules: see above)."""
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
