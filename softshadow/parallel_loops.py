"""numba for compiled loops that run on several threads (``parallel=True``, ``prange``).

numba runs them on OpenMP here (its ``omp`` threading layer), whose idle threads by default
spin for a while after each loop before they sleep. On a small, shared machine that spinning
takes the cores from the renderer's other thread and from other processes: measured on the
2-core test machine at load ~4, a scene frame took twice the CPU time and twice the wall time.
``OMP_WAIT_POLICY=PASSIVE`` (unless already set) makes them sleep at once. OpenMP reads it when
it is loaded, which numba does at the first parallel loop, so every factory of a parallel loop
gets numba from here.
"""

from __future__ import annotations

import os

__all__ = ["parallel_numba"]


def parallel_numba():
    """The numba module, with OpenMP's idle threads set to sleep rather than spin (see above)."""
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    import numba
    return numba
