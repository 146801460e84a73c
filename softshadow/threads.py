"""Threads: the process's BLAS threads, fixed once at each entry point, and work shared with a
second thread (NumPy only, no JAX)."""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Executor
from typing import TypeVar

from threadpoolctl import threadpool_limits

__all__ = ["one_blas_thread", "share"]

T = TypeVar("T")
U = TypeVar("U")


def one_blas_thread():
    """A context manager that limits NumPy's BLAS to one thread (``threadpoolctl``).

    The entry points (the ``softshadow`` command, ``fitting.fit_photos``,
    ``data_synth.synthesize``) run inside it, and the code below them writes its products
    plainly (``@``, einsum). Why: OpenBLAS threads keep spinning after each call and starve
    XLA's and Embree's threads on a small machine; renders and solves ran 10-20x slower after
    one tall matrix product, and a (1.9M, 2) @ (2, 3) product took 3x longer with two BLAS
    threads than with one (2 cores). The arrays BLAS sees here are small or tall and thin, so
    one thread costs nothing.
    """
    # threadpoolctl limits only the libraries loaded at that moment, and with the packages'
    # imports deferred (softshadow and fitting load modules on first use) an entry point may run
    # before any of them: load the three OpenBLAS copies a fit uses (NumPy's, SciPy's, OpenCV's).
    import cv2  # noqa: F401
    import numpy  # noqa: F401
    import scipy.linalg  # noqa: F401
    return threadpool_limits(limits=1, user_api="blas")


def share(pool: Executor, theirs: Callable[[], T], mine: Callable[[], U],
          then: Callable[[], None] | None = None) -> tuple[T, U]:
    """(theirs(), mine()): theirs on the pool's thread while this one runs mine, or here after
    mine when the pool has not started it by then (busy with work given before), so no caller
    waits behind that work. then(), optional: called once theirs is handed over, before mine.
    Neither is left running when this returns or raises."""
    pending = pool.submit(theirs)
    if then is not None:
        then()
    try:
        out = mine()
    finally:
        if not pending.cancel():
            pending.exception()  # waited for; its error is raised by result() below
    return (theirs() if pending.cancelled() else pending.result()), out
