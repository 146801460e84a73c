"""Where and with what a benchmark ran: date, machine and versions (JSON-ready)."""

from __future__ import annotations

import datetime
import os
import platform
from importlib import metadata

__all__ = ["environment", "load_average"]

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
