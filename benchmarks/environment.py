"""Where and with what a benchmark ran: date, machine and versions (JSON-ready)."""

from __future__ import annotations

import datetime
import functools
import os
import platform
import time
from importlib import metadata

import numpy as np

__all__ = ["environment", "load_average", "two_thread_slowdown"]

_PACKAGES = ("softshadow", "jax", "jaxlib", "numpy", "scipy", "opencv-contrib-python-headless", "trimesh",
             "embreex", "fast-simplification", "equinox", "optimistix", "matplotlib")


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _memory_gb() -> float | None:
    try:
        return round(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2 ** 30, 1)
    except (ValueError, OSError, AttributeError):
        return None


def load_average() -> list[float] | None:
    """The system's load average over 1, 5 and 15 minutes (runnable processes), if known."""
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except (OSError, AttributeError):
        return None


def two_thread_slowdown(repeats: int = 3) -> float:
    """How much of a second core the machine gives now: the time of the same small arithmetic
    (L1-resident, about a millisecond) done by two threads at once, each all of it, over its time
    on one thread (the median of ``repeats`` pairs; both runs wake numba's threads alike). About 1
    when two cores are free; towards 2 when the two threads share one core's worth (another
    process busy, or one core only). A slowdown of memory that both threads' work would feel
    alike does not show here.
    """
    kernel = _probe_kernel()
    x = np.linspace(0.0, 1.0, 1024)
    ratios = []
    for _ in range(repeats):
        seconds = []
        for threads in (1, 2):
            t = time.perf_counter()
            kernel(x, 8000, threads)
            seconds.append(time.perf_counter() - t)
        ratios.append(seconds[1] / seconds[0])
    return round(float(np.median(ratios)), 2)


@functools.cache
def _probe_kernel():
    import numba

    import softshadow  # noqa: F401  (before numba's first parallel loop: its idle threads then sleep)

    @numba.njit(cache=True, nogil=True, parallel=True)
    def kernel(x, repeats, threads):
        out = np.zeros(threads)
        for t in numba.prange(threads):
            acc = np.zeros(x.shape[0])
            for _ in range(repeats):
                for i in range(x.shape[0]):
                    acc[i] = acc[i] * 0.999 + x[i]
            out[t] = acc.sum()
        return out

    kernel(np.zeros(8), 1, 1)  # compiled (or loaded) before any timing
    return kernel


def environment() -> dict:
    versions = {"python": platform.python_version()}
    for name in _PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    cpus = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else None
    return {"date_utc": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
            "machine": {"cpu": _cpu_model(), "cores": len(cpus) if cpus else os.cpu_count(),
                        "memory_gb": _memory_gb(), "platform": platform.platform(),
                        "load_average_1_5_15_min": load_average()},
            "versions": versions}
