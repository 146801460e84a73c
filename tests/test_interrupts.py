"""A Ctrl-C that arrives during a garbage-collection callback still interrupts the command."""
import gc
import os
import signal
import sys
import time

import pytest

from softshadow_cli.interrupts import ctrl_c_never_swallowed


@pytest.fixture
def python_sigint():
    # The test runner may have SIGINT ignored (inherited); give Python's default handler for the test.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def _ctrl_c_during_gc_callback(wait_s: float) -> None:
    def callback(phase, info):
        if phase == "start":
            os.kill(os.getpid(), signal.SIGINT)
            sum(range(10_000))  # bytecodes inside the callback: the handler runs here

    gc.callbacks.append(callback)
    try:
        gc.collect()
    finally:
        gc.callbacks.remove(callback)
    deadline = time.monotonic() + wait_s
    while time.monotonic() < deadline:
        time.sleep(0.01)


def test_plain_python_swallows_it(python_sigint, monkeypatch):
    # The failure this module exists for: Python ignores the KeyboardInterrupt (prints
    # "Exception ignored in: gc callback") and goes on.
    ignored = []
    monkeypatch.setattr(sys, "unraisablehook", lambda u: ignored.append(u.exc_type))
    _ctrl_c_during_gc_callback(0.5)
    assert ignored == [KeyboardInterrupt]


def test_ctrl_c_in_gc_callback_is_delivered(python_sigint):
    # Swallowed, the interrupt would let the 30 s wait run out; the bound leaves room for a full
    # collection of a large heap on a loaded machine (3.5 s seen at load 15).
    started = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        with ctrl_c_never_swallowed():
            _ctrl_c_during_gc_callback(30.0)
    assert time.monotonic() - started < 15.0
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_ordinary_ctrl_c_raises_at_once(python_sigint):
    with pytest.raises(KeyboardInterrupt):
        with ctrl_c_never_swallowed():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(5.0)


def test_ignored_sigint_stays_ignored():
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with ctrl_c_never_swallowed():
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)
