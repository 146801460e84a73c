"""Ctrl-C that is never swallowed and never crashes the process, wherever it lands.

Python runs a signal's handler in the main thread at the next bytecode, wherever that is, and
a KeyboardInterrupt raised there can go wrong in three ways:

- **swallowed and printed**: inside a garbage-collection callback (JAX registers one), a ctypes
  callback (numba's compilation cache, through llvmlite) or a ``__del__``, Python prints
  "Exception ignored in ..." with a traceback and goes on;
- **crashing**: inside a C++ extension module's initialisation (an import of jaxlib), the
  exception crosses C++ code that cannot carry it: ``terminate`` (abort) or a segfault;
- **swallowed in silence**: by a library's bare ``except:``.

So the handler does not raise where it cannot (a garbage-collection callback, an extension
module being imported): it delivers the Ctrl-C again a moment later. An exception that Python
would print as "ignored" is not printed and delivered again. And a Ctrl-C that has not
reached the command a moment later (the main thread is not handling it) is delivered again.
"""
from __future__ import annotations

import _thread
import gc
import importlib.machinery
import signal
import sys
import threading
from contextlib import contextmanager

__all__ = ["ctrl_c_never_swallowed", "ctrl_c_pressed", "quiet_after_interrupt"]

#: Seconds between a deferred or swallowed Ctrl-C and its next delivery.
RETRY_S = 0.05
#: Seconds after which a Ctrl-C the main thread is not handling is delivered again.
WATCH_S = 1.0

# Native code that cannot carry a Python exception through it: an extension module's
# initialisation (it may call back into Python: jaxlib builds its enums there).
_NATIVE_IMPORT = frozenset({importlib.machinery.ExtensionFileLoader.exec_module.__code__,
                            importlib.machinery.ExtensionFileLoader.create_module.__code__})


class _State:
    """What the handler needs between calls: whether it is installed, whether Ctrl-C was
    pressed and the pending timers."""

    def __init__(self) -> None:
        self.active = False
        self.pressed = False
        self.lock = threading.Lock()
        self.timers: list[threading.Timer] = []

    def later(self, seconds: float, fn) -> None:
        timer = threading.Timer(seconds, fn)
        timer.daemon = True
        with self.lock:
            self.timers = [t for t in self.timers if t.is_alive()] + [timer]
        timer.start()

    def stop(self) -> None:
        with self.lock:
            self.active = False
            timers, self.timers = self.timers, []
        for t in timers:
            t.cancel()


_state = _State()


def ctrl_c_pressed() -> bool:
    """Whether Ctrl-C was pressed within the current ``ctrl_c_never_swallowed`` block (also when
    the KeyboardInterrupt was turned into another exception on its way up)."""
    return _state.pressed


def _deliver(wake: bool = False) -> None:
    """Deliver the Ctrl-C again: the handler runs at the main thread's next bytecode. With
    ``wake``, as a real signal to the main thread, which also ends a blocking wait there (a
    sleep, a lock); else only as Python's flag, which never interrupts native code."""
    with _state.lock:
        if not _state.active:
            return
        if wake and hasattr(signal, "pthread_kill"):
            signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)
        else:
            _thread.interrupt_main()


def _cannot_raise_here(frame) -> bool:
    """Whether the handler's frame lies inside a garbage-collection callback or an extension
    module's initialisation."""
    gc_codes = {getattr(callback, "__code__", None) for callback in gc.callbacks}
    gc_codes.discard(None)
    while frame is not None:
        if frame.f_code in gc_codes or frame.f_code in _NATIVE_IMPORT:
            return True
        frame = frame.f_back
    return False


def _handling_interrupt(main_ident: int) -> bool:
    """Whether the main thread is handling a KeyboardInterrupt (in an ``except`` or ``finally``
    on its way up, or an exception raised while handling one)."""
    exc = sys._current_exceptions().get(main_ident)
    if isinstance(exc, tuple):  # Python < 3.12: (type, value, traceback)
        exc = exc[1]
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__context__ or exc.__cause__
    return False


def _watch(main_ident: int) -> None:
    """A moment after a Ctrl-C: if the main thread is not handling it, it was swallowed:
    deliver it again, and look again a moment later. Once it is handled, stop watching."""
    if not _state.active or _handling_interrupt(main_ident):
        return
    # A real signal ends a blocking wait; but not while the main thread is still where it cannot
    # raise (native code there may not expect an interrupted system call).
    if not _cannot_raise_here(sys._current_frames().get(main_ident)):
        _deliver(wake=True)
    _state.later(WATCH_S, lambda: _watch(main_ident))


def _interrupt(signum, frame) -> None:
    if not _state.active:
        return  # a delivery that arrives while the block is being left: the command is ending
    first = not _state.pressed
    _state.pressed = True
    if first:
        _state.later(WATCH_S, lambda: _watch(threading.main_thread().ident))
    if _cannot_raise_here(frame):
        _state.later(RETRY_S, _deliver)
        return
    raise KeyboardInterrupt


def _unraisable(previous):
    """sys.unraisablehook: a KeyboardInterrupt Python would print and ignore (a callback, a
    ``__del__``) is delivered again instead."""
    def hook(unraisable) -> None:
        if _state.active and unraisable.exc_type is not None and issubclass(unraisable.exc_type, KeyboardInterrupt):
            _state.later(RETRY_S, _deliver)
            return
        if _state.pressed:
            return  # a __del__ of an object the Ctrl-C left half-built: the command is ending anyway
        previous(unraisable)
    return hook


@contextmanager
def ctrl_c_never_swallowed():
    """Within the block, a Ctrl-C raises KeyboardInterrupt in the main thread wherever it lands
    (see the module's text). Leaves SIGINT alone when it is not Python's default handler
    (ignored by the parent, or set by the caller) or when not on the main thread."""
    # A press from an earlier block (an earlier command in the same process) is not this block's.
    _state.pressed = False
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
        yield
        return
    previous_hook = sys.unraisablehook
    _state.active = True
    sys.unraisablehook = _unraisable(previous_hook)
    previous = signal.signal(signal.SIGINT, _interrupt)
    try:
        yield
    finally:
        try:
            _state.stop()
        finally:
            signal.signal(signal.SIGINT, previous)
            sys.unraisablehook = previous_hook
            if _state.pressed:
                _forget_unhandled_interrupt()


def _forget_unhandled_interrupt() -> None:
    """Clear CPython's record of a KeyboardInterrupt that left code run by ``exec`` of a string
    (dataclasses and namedtuples are made that way), even though the command caught it later:
    with the record set, the interpreter ends by killing itself with SIGINT (status -2)
    instead of exiting with the command's status. Running any code through the same path
    clears it."""
    try:
        import ctypes
        ctypes.pythonapi.PyRun_SimpleString(b"pass")
    except (ImportError, AttributeError, OSError):
        pass


def quiet_after_interrupt() -> None:
    """For a command that ends because of Ctrl-C: errors Python would print as "Exception ignored"
    from now on (a ``__del__`` of an object the interruption left half-built, say llvmlite's) are
    dropped; the command has said, in one line, that it was interrupted."""
    sys.unraisablehook = lambda unraisable: None
