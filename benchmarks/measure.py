"""Measuring one case: the median wall time of repeated runs after a warm-up, and its peak memory.

Peak memory is the process's resident-set high-water mark (``VmHWM``) over one more run after
the timed ones, reset before it through ``/proc/self/clear_refs`` (Linux); ``peak_mb`` is that
mark and ``peak_extra_mb`` how far it rose above the resident set before the run (what the case
itself needed, XLA's CPU buffers included, which Python's tracemalloc does not see). Before that
run the garbage is collected and glibc's free heap pages are handed back (``malloc_trim``): else
the run reuses pages the warm-up already faulted in, and its peak reads 0 (as it did before
2026-11-24). That run is not timed: pages faulted afresh would slow it. Elsewhere both are None.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import statistics
import time
from pathlib import Path

__all__ = ["Timing", "timed", "peak_memory"]

_STATUS = Path("/proc/self/status")


def _status_kb(field: str) -> int | None:
    try:
        for line in _STATUS.read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1])
    except OSError:
        return None
    return None


_M_MMAP_THRESHOLD = -3  # glibc's mallopt parameter


def _trim_heap() -> None:
    """Hand glibc's free heap pages back to the system, and fix its mmap threshold at 1 MB, so
    that large buffers are mapped afresh and unmapped when freed (glibc otherwise raises the
    threshold after the first large free, up to 32 MB, and later buffers reuse resident heap
    pages: a 32 MB output then read 0 MB extra in 5 of 30 runs). No-op without glibc."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.mallopt(_M_MMAP_THRESHOLD, 1 << 20)
        libc.malloc_trim(0)
    except (OSError, AttributeError):
        pass


def _reset_peak() -> bool:
    try:
        Path("/proc/self/clear_refs").write_text("5")
        return True
    except OSError:
        return False


class Timing(dict):
    """{"median_ms", "min_ms", "repeats", "peak_mb", "peak_extra_mb"}."""


def timed(fn, repeats: int = 5, warmup: int = 1, memory: bool = True) -> Timing:
    """Run ``fn`` ``warmup`` times (compilation), then ``repeats`` times timed, then (``memory``)
    once more for its peak memory (else the peaks are None)."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    peak_mb, extra_mb = peak_memory(fn) if memory else (None, None)
    return Timing(median_ms=round(1000.0 * statistics.median(times), 3), min_ms=round(1000.0 * min(times), 3),
                  repeats=repeats, peak_mb=peak_mb, peak_extra_mb=extra_mb)


def peak_memory(fn) -> tuple[float | None, float | None]:
    """(peak_mb, peak_extra_mb) of one run of ``fn`` (module docstring); (None, None) off Linux."""
    gc.collect(1)  # the young generations: a full collection takes ~0.3 s with JAX loaded
    _trim_heap()
    before = _status_kb("VmRSS")
    if not _reset_peak():
        return None, None
    fn()
    peak = _status_kb("VmHWM")
    if peak is None:
        return None, None
    return round(peak / 1024.0, 1), None if before is None else round((peak - before) / 1024.0, 1)
