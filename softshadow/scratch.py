"""What a renderer keeps between frames: large per-frame arrays, and results whose inputs did not change.

A 640 x 480 frame needs tens of megabytes of per-pixel arrays. Freed, the C allocator returns
such blocks to the system, and the next frame's first writes fault every page back in: measured
here, 0.2-0.4 ms per megabyte, a fifth of a frame. ``Scratch`` keeps one buffer per name and
hands out views of it; the arrays of the last call are overwritten by the next (copy what you
keep). Not for use from two threads at once under the same name.

``Scratch.memo`` keeps one result per name with the inputs it was made from (a projector's
shadow map while neither the projector nor the casters move): made again only when an input
differs. Arrays among the inputs are compared by value (a copy is kept, so an array changed in
place is seen), other objects by identity, numbers and strings by value.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["Scratch", "scratch_array"]


class Scratch:
    """Named buffers, each grown to the largest size asked for and reused after; named results
    kept with their inputs (``memo``)."""

    def __init__(self):
        self._buffers: dict[str, np.ndarray] = {}
        self._memo: dict[str, tuple[tuple, Any]] = {}
        self._sizes: dict[str, int] = {}

    def array(self, name: str, shape, dtype=np.float64) -> np.ndarray:
        """An uninitialised array of ``shape`` and ``dtype``: a view of the buffer kept as ``name``."""
        dtype = np.dtype(dtype)
        shape = (int(shape),) if np.ndim(shape) == 0 else tuple(int(s) for s in shape)
        size = math.prod(shape)  # not np.prod: this runs some twenty times a frame
        buf = self._buffers.get(name)
        if buf is None or buf.dtype != dtype or buf.size < size:
            buf = np.empty(max(size, 1), dtype)
            self._buffers[name] = buf
        return buf[:size].reshape(shape)

    def capacity(self, name: str, n: int, grow: Callable[[int], int]) -> int:
        """A size kept under ``name`` that holds ``n``: the kept one while n fits in it, else
        ``grow(n)`` (>= n), kept from then on. Arrays padded to it keep their shape while the
        count moves below it."""
        kept = self._sizes.get(name)
        if kept is None or n > kept:
            kept = int(grow(n))
            if kept < n:
                raise ValueError(f"capacity {name!r}: grow({n}) gave {kept}, less than {n}")
            self._sizes[name] = kept
        return kept

    def memo(self, name: str, inputs: tuple, make: Callable[[], Any]) -> Any:
        """``make()``, or the result kept under ``name`` when it was made from the same ``inputs``
        (a tuple: arrays by value, numbers and strings by value, other objects by identity)."""
        kept = self._memo.get(name)
        if kept is not None and _same(kept[0], inputs):
            return kept[1]
        self._memo.pop(name, None)  # a failing make() leaves nothing stale behind
        value = make()
        self._memo[name] = (_frozen(inputs), value)
        return value


def _frozen(inputs: tuple) -> tuple:
    """The inputs as kept: arrays copied (an array changed in place after is then seen)."""
    return tuple(np.array(x, copy=True) if isinstance(x, np.ndarray) else x for x in inputs)


def _same(kept: tuple, inputs: tuple) -> bool:
    if len(kept) != len(inputs):
        return False
    for a, b in zip(kept, inputs):
        if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
            if not (isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.dtype == b.dtype
                    and a.shape == b.shape and np.array_equal(a, b)):
                return False
        elif isinstance(a, (int, float, str, bool, bytes, type(None))):
            if type(a) is not type(b) or a != b:
                return False
        elif a is not b:
            return False
    return True


def scratch_array(scratch: Scratch | None, name: str, shape, dtype=np.float64) -> np.ndarray:
    """``scratch.array(name, shape, dtype)``, or a new array without scratch buffers."""
    if scratch is None:
        return np.empty(shape, dtype)
    return scratch.array(name, shape, dtype)
