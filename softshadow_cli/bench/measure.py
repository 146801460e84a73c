"""Measuring one case: the median wall time of repeated runs after a warm-up, and its peak memory.

Peak memory is the process's resident-set high-water mark (``VmHWM``) during the timed runs,
reset before them through ``/proc/self/clear_refs`` (Linux); ``peak_mb`` is that mark and
``peak_extra_mb`` how far it rose above the resident set before the case (what the case itself
needed, XLA's buffers included, which Python's tracemalloc does not see). Elsewhere both are None.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

__all__ = ["Timing", "timed"]

_STATUS = Path("/proc/self/status")


def _status_kb(field: str) -> int | None:
    try:
        for line in _STATUS.read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1])
    except OSError:
        return None
    return None


def _reset_peak() -> bool:
    try:
        Path("/proc/self/clear_refs").write_text("5")
        return True
    except OSError:
        return False


class Timing(dict):
    """{"median_ms", "min_ms", "repeats", "peak_mb", "peak_extra_mb"}."""


def timed(fn, repeats: int = 5, warmup: int = 1) -> Timing:
    """Run ``fn`` ``warmup`` times (compilation), then ``repeats`` times timed."""
    for _ in range(warmup):
        fn()
    before = _status_kb("VmRSS")
    can_reset = _reset_peak()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    peak = _status_kb("VmHWM") if can_reset else None
    return Timing(median_ms=round(1000.0 * statistics.median(times), 3), min_ms=round(1000.0 * min(times), 3),
                  repeats=repeats, peak_mb=None if peak is None else round(peak / 1024.0, 1),
                  peak_extra_mb=None if peak is None or before is None else round((peak - before) / 1024.0, 1))
