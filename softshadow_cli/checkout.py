"""Find the source checkout's ``benchmarks`` package (it is not installed with the wheel)."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path
from types import ModuleType

__all__ = ["import_benchmarks"]


def import_benchmarks() -> ModuleType | None:
    """The ``benchmarks`` package beside this command's source (an editable install of a checkout),
    or ``None`` when softshadow was installed from a wheel."""
    root = Path(__file__).resolve().parents[1]
    if not (root / "benchmarks" / "__init__.py").is_file():
        return None
    if str(root) not in sys.path:
        sys.path.insert(0, str(root))
    return importlib.import_module("benchmarks")
