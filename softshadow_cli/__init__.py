"""softshadow_cli: the ``softshadow`` command and its benchmarks.

The top layer: it imports ``softshadow`` (the renderer), ``scene``,
``fitting`` and ``data_synth``, and nothing imports it.
"""

from .main import main

__all__ = ["main"]
