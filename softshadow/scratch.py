"""Arrays kept between frames, so that a renderer's large per-frame arrays are not fresh memory.

A 640 x 480 frame needs tens of megabytes of per-pixel arrays. Freed, the C allocator returns
such blocks to the system, and the next frame's first writes fault every page back in: measured
here, 0.2-0.4 ms per megabyte, a fifth of a frame. ``Scratch`` keeps one buffer per name and
hands out views of it; the arrays of the last call are overwritten by the next (copy what you
keep). Not for use from two threads at once under the same name.
"""

from __future__ import annotations

import numpy as np

__all__ = ["Scratch", "scratch_array"]


class Scratch:
    """Named buffers, each grown to the largest size asked for and reused after."""

    def __init__(self):
        self._buffers: dict[str, np.ndarray] = {}

    def array(self, name: str, shape, dtype=np.float64) -> np.ndarray:
        """An uninitialised array of ``shape`` and ``dtype``: a view of the buffer kept as ``name``."""
        dtype = np.dtype(dtype)
        shape = tuple(int(s) for s in np.atleast_1d(shape))
        size = int(np.prod(shape))
        buf = self._buffers.get(name)
        if buf is None or buf.dtype != dtype or buf.size < size:
            buf = np.empty(max(size, 1), dtype)
            self._buffers[name] = buf
        return buf[:size].reshape(shape)


def scratch_array(scratch: Scratch | None, name: str, shape, dtype=np.float64) -> np.ndarray:
    """``scratch.array(name, shape, dtype)``, or a new array without scratch buffers."""
    if scratch is None:
        return np.empty(shape, dtype)
    return scratch.array(name, shape, dtype)
