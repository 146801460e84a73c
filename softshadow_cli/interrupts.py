"""Ctrl-C that is never swallowed.

Python runs a signal's handler in the main thread at the next bytecode, wherever that is. When it
is inside a garbage-collection callback (JAX registers one), the KeyboardInterrupt it raises is
"ignored" by Python and the command goes on. This handler sees that case and delivers the Ctrl-C
again a moment later, once the callback has returned.
"""
from __future__ import annotations

import _thread
import gc
import signal
import threading
from contextlib import contextmanager

__all__ = ["ctrl_c_never_swallowed"]


def _inside_gc_callback(frame) -> bool:
    codes = {getattr(callback, "__code__", None) for callback in gc.callbacks}
    codes.discard(None)
    while frame is not None:
        if frame.f_code in codes:
            return True
        frame = frame.f_back
    return False


def _interrupt(signum, frame) -> None:
    if _inside_gc_callback(frame):
        threading.Timer(0.05, _thread.interrupt_main).start()
        return
    raise KeyboardInterrupt


@contextmanager
def ctrl_c_never_swallowed():
    """Within the block, a Ctrl-C raises KeyboardInterrupt in the main thread even when it arrives
    during a garbage-collection callback. Leaves SIGINT alone when it is not Python's default
    handler (ignored by the parent, or set by the caller) or when not on the main thread."""
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
        yield
        return
    previous = signal.signal(signal.SIGINT, _interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
