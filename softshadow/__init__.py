"""softshadow: a differentiable expanded-shadow-volume soft shadow renderer in JAX.

The model (Shoji, Murayama and Konno): the hard shadow volume of a mesh under the sun, expanded and
contracted at its silhouette by moving the light direction to L +- k N, with alpha ramping between the
two silhouettes, and the umbra at brightness rho (docs/renderer.md). Projector scenes with shadow maps
and levels of detail follow Dowling (docs/projector.md).

The names here are the public API. ``softshadow.internal`` holds the building blocks the fitter and the
synthesiser use (plans, occluders, shadow maps): usable, but they may change between releases.
"""

import os as _os
import sys as _sys

import lazy_loader as _lazy

from ._version import __version__ as __version__

# numba's cache of the compiled loops goes to the user's cache folder, not beside the installed
# modules: an installed package may be read-only, and cache files pip does not know of would outlive
# an uninstall as a bare ``softshadow/`` folder that hides a later editable install. NUMBA_CACHE_DIR,
# when set, wins.
if not _os.environ.get("NUMBA_CACHE_DIR"):
    _os.environ["NUMBA_CACHE_DIR"] = _os.path.join(_os.path.expanduser("~"), ".cache", "softshadow", "numba")
    if "numba.core.config" in _sys.modules:  # numba read its settings already
        _sys.modules["numba.core.config"].CACHE_DIR = _os.environ["NUMBA_CACHE_DIR"]

# numba's OpenMP threads sleep when idle instead of spinning (``parallel_loops``): set before any
# parallel loop of the process starts them, which may be the user's own.
from .parallel_loops import sleep_idle_threads as _sleep_idle_threads  # noqa: E402

_sleep_idle_threads()

# The public names are listed in ``__init__.pyi`` (which type checkers and the API reference read too).
# Each module is imported when one of its names is first used (PEP 562, ``lazy_loader``): a process
# that needs only the NumPy/OpenCV steps (a photo without geometry, ``--help``) never loads JAX or
# trimesh, which take seconds.
__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
__all__ = sorted(set(__all__) - {"internal"} | {"__version__"})
